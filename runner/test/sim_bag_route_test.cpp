// A simulated flight reaches the pipeline the same way from its bag and in process: the scans
// BagScanSource reads from the bag simulate_flight writes (FlightBagWriter, write_mission_scan)
// and those SimScanSource generates for the same options are equal bit for bit (stamps, odometry,
// points, point times and the odometry across each sweep), so both routes map to the same
// trajectory.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <string>

#include "runner/bag_scan_source.h"
#include "runner/sim_scan_source.h"
#include "sim/sim_flight_bag.h"
#include "sim/sim_mission.h"
#include "sim/sim_mission_bag.h"

namespace covox {
namespace {

// The start of the default flight (its yaw sweeps and turns move the sensor within each sweep)
// with a small LiDAR.
sim::SimulationOptions small_flight(bool instantaneous) {
  sim::SimulationOptions options;
  options.seed = 3;
  options.flight.variation_seed = options.seed;
  options.lidar.columns = 64;
  options.lidar.rows = 16;
  options.lidar.instantaneous = instantaneous;
  return options;
}

std::string write_flight_bag(const sim::SimulatedMission& mission, const std::string& name) {
  const std::string path = ::testing::TempDir() + "/" + name + "_" + std::to_string(::getpid());
  sim::FlightBagWriter writer(path);
  for (size_t k = 0; k < mission.size(); ++k)
    sim::write_mission_scan(&writer, mission, k, mission.scan(k));
  writer.close();
  return path;
}

bool same_pose(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return a.matrix() == b.matrix();
}

void expect_same_scan(const tools::SourceScan& bag, const tools::SourceScan& simulated, size_t k) {
  EXPECT_EQ(bag.stamp_s, simulated.stamp_s) << k;
  EXPECT_TRUE(same_pose(bag.T_odom_sensor, simulated.T_odom_sensor)) << k;
  ASSERT_EQ(bag.points_sensor_m.size(), simulated.points_sensor_m.size()) << k;
  EXPECT_GT(bag.points_sensor_m.size(), 100u) << k;
  for (size_t i = 0; i < bag.points_sensor_m.size(); ++i) {
    ASSERT_EQ(bag.points_sensor_m[i].x, simulated.points_sensor_m[i].x) << k << " " << i;
    ASSERT_EQ(bag.points_sensor_m[i].y, simulated.points_sensor_m[i].y) << k << " " << i;
    ASSERT_EQ(bag.points_sensor_m[i].z, simulated.points_sensor_m[i].z) << k << " " << i;
  }
  EXPECT_TRUE(bag.point_times_s == simulated.point_times_s) << k;
  EXPECT_EQ(bag.sweep.known, simulated.sweep.known) << k;
  EXPECT_EQ(bag.sweep.begin_s, simulated.sweep.begin_s) << k;
  EXPECT_EQ(bag.sweep.end_s, simulated.sweep.end_s) << k;
  EXPECT_TRUE(same_pose(bag.sweep.T_odom_sensor_begin, simulated.sweep.T_odom_sensor_begin))
      << k << ": odometry at the first point time\n"
      << bag.sweep.T_odom_sensor_begin.matrix() << "\n"
      << simulated.sweep.T_odom_sensor_begin.matrix();
  EXPECT_TRUE(same_pose(bag.sweep.T_odom_sensor_end, simulated.sweep.T_odom_sensor_end))
      << k << ": odometry at the last point time\n"
      << bag.sweep.T_odom_sensor_end.matrix() << "\n"
      << simulated.sweep.T_odom_sensor_end.matrix();
}

TEST(SimBagRoute, InProcessScansEqualTheBagsBitForBit) {
  const size_t scans = 12;
  for (const bool instantaneous : {false, true}) {
    SCOPED_TRACE(instantaneous ? "instantaneous scans" : "distorted scans");
    const sim::SimulationOptions options = small_flight(instantaneous);
    const std::string path = write_flight_bag(sim::SimulatedMission(options, scans), "route.bag");
    tools::BagScanOptions bag_options;
    bag_options.min_range_m = 0.5;
    tools::BagScanSource from_bag(path, bag_options);
    tools::SimScanSource in_process(options, bag_options.min_range_m, scans);
    ASSERT_EQ(from_bag.size(), scans);
    ASSERT_EQ(in_process.size(), scans);
    tools::SourceScan bag_scan, simulated_scan;
    for (size_t k = 0; k < scans; ++k) {
      ASSERT_TRUE(from_bag.next(&bag_scan));
      ASSERT_TRUE(in_process.next(&simulated_scan));
      EXPECT_EQ(bag_scan.sweep.known, !instantaneous) << k;
      expect_same_scan(bag_scan, simulated_scan, k);
    }
    EXPECT_FALSE(from_bag.next(&bag_scan));
    EXPECT_FALSE(in_process.next(&simulated_scan));
    // The reference: the same positions at the same stamps.
    ASSERT_EQ(from_bag.reference().size(), in_process.reference().size());
    for (size_t k = 0; k < scans; ++k) {
      const io::StampedPose& a = from_bag.reference().poses[k];
      const io::StampedPose& b = in_process.reference().poses[k];
      EXPECT_EQ(a.timestamp_s, b.timestamp_s) << k;
      EXPECT_TRUE(a.position_m == b.position_m) << k;
    }
    std::remove(path.c_str());
  }
}

}  // namespace
}  // namespace covox

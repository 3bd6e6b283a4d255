// The LiDAR simulator: deterministic from its seed, exact against analytic surfaces, its
// hierarchy finds the same hits as testing every primitive, the odometry drifts at least as much
// as configured, and flight bags are byte-identical for a seed and read back what was written.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>

#include "bag_scan_source.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/rosbag_reader.h"
#include "sim_flight.h"
#include "sim_flight_bag.h"
#include "sim_lidar.h"
#include "sim_random.h"
#include "sim_site.h"
#include "sim_world.h"

namespace covox {
namespace sim {
namespace {

LidarConfig exact_lidar(int columns = 128, int rows = 32) {
  LidarConfig config;
  config.columns = columns;
  config.rows = rows;
  config.range_noise_m = 0.0;
  config.dropout_probability = 0.0;
  return config;
}

Eigen::Isometry3d pose_at(const Eigen::Vector3d& position_m, double yaw_rad = 0.0) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = position_m;
  return pose;
}

Eigen::Vector3d to_world(const Eigen::Isometry3d& pose, const Vec3f& p) {
  return pose * Eigen::Vector3d(p.x, p.y, p.z);
}

TEST(Simulator, SameSeedGivesIdenticalScansAndOdometry) {
  const FlightConfig flight;
  const Figure8Path path(flight);
  const std::vector<StampedIsometry> truth = simulate_truth(path, flight);
  LidarConfig lidar;
  lidar.columns = 128;  // noise and dropouts on, as in a real run
  std::vector<std::vector<Vec3f>> runs[2];
  std::vector<StampedIsometry> odometry[2];
  for (int run = 0; run < 2; ++run) {
    const Site site = build_site(SiteConfig(), path, 42);
    odometry[run] = simulate_odometry(truth, DriftConfig(), 42);
    for (size_t k : {size_t{0}, truth.size() / 4, truth.size() / 2}) {
      runs[run].push_back(simulate_scan(site.world, lidar, truth[k].pose, stream_seed(42, k)));
    }
  }
  ASSERT_EQ(runs[0].size(), runs[1].size());
  for (size_t s = 0; s < runs[0].size(); ++s) {
    ASSERT_GT(runs[0][s].size(), 1000u);
    ASSERT_EQ(runs[0][s].size(), runs[1][s].size());
    for (size_t i = 0; i < runs[0][s].size(); ++i) {
      ASSERT_EQ(runs[0][s][i].x, runs[1][s][i].x);
      ASSERT_EQ(runs[0][s][i].y, runs[1][s][i].y);
      ASSERT_EQ(runs[0][s][i].z, runs[1][s][i].z);
    }
  }
  for (size_t k = 0; k < truth.size(); ++k) {
    ASSERT_TRUE(odometry[0][k].pose.isApprox(odometry[1][k].pose, 0.0));
  }
  // Another seed changes the noise.
  const Site site = build_site(SiteConfig(), path, 42);
  const std::vector<Vec3f> other =
      simulate_scan(site.world, lidar, truth[0].pose, stream_seed(43, 0));
  bool differs = other.size() != runs[0][0].size();
  for (size_t i = 0; !differs && i < other.size(); ++i) differs = other[i].x != runs[0][0][i].x;
  EXPECT_TRUE(differs);
}

TEST(Simulator, ALargerFigureEightGetsAProportionallyBuiltUpSite) {
  // The default flight's site, and any figure 8 of the default lobes, keep the configured counts.
  FlightConfig flight;
  const SiteConfig base;
  for (double path_m : {400.0, 495.0, 3600.0}) {
    flight.path_length_m = path_m;
    const SiteConfig same = base.scaled_to(Figure8Path(flight));
    EXPECT_EQ(same.extra_buildings, base.extra_buildings) << path_m;
    EXPECT_EQ(same.trees, base.trees) << path_m;
  }
  // Lobes twice as long and a lap twice as long: four times the area, four times the objects.
  flight.lobe_half_length_m = 2.0 * FlightConfig().lobe_half_length_m;
  flight.path_length_m = 2.0 * 9.0 * flight.lobe_half_length_m;
  const Figure8Path large(flight);
  const SiteConfig scaled = base.scaled_to(large);
  EXPECT_NEAR(scaled.extra_buildings, 4 * base.extra_buildings, 1);
  EXPECT_NEAR(scaled.rubble_piles, 4 * base.rubble_piles, 1);
  EXPECT_NEAR(scaled.poles, 4 * base.poles, 2);
  EXPECT_NEAR(scaled.trees, 4 * base.trees, 2);
  const Site site = build_site(scaled, large, 5);
  EXPECT_EQ(site.buildings.size(), static_cast<size_t>(1 + scaled.extra_buildings));
}

TEST(Simulator, RangesMatchAnalyticDistancesToAPlane) {
  World world;
  world.add(Plane{});  // z = 0, facing up
  world.build();
  const LidarConfig lidar = exact_lidar();
  const Eigen::Isometry3d pose = pose_at(Eigen::Vector3d(1.0, -2.0, 2.0), 0.4);
  const std::vector<Vec3f> points = simulate_scan(world, lidar, pose, 1);
  // Every beam looking down hits the plane at range height / sin(-elevation), and returns when
  // that is within the range limit.
  int downward = 0;
  for (int row = 0; row < lidar.rows; ++row) {
    const double down = -beam_direction(lidar, row, 0).z();
    if (down > 0.0 && 2.0 / down <= lidar.max_range_m) downward += lidar.columns;
  }
  ASSERT_EQ(static_cast<int>(points.size()), downward);
  for (const Vec3f& p : points) {
    const Eigen::Vector3d local(p.x, p.y, p.z);
    const double expected = 2.0 / (-local.normalized().z());
    EXPECT_NEAR(local.norm(), expected, 1e-5 * expected);
    EXPECT_NEAR(to_world(pose, p).z(), 0.0, 1e-5 * expected);
  }
}

TEST(Simulator, RangesMatchAnalyticDistancesInsideABoxRoom) {
  World world;
  Box room;
  room.centre_m = Eigen::Vector3d(0.5, 0.0, 1.0);
  room.half_extent_m = Eigen::Vector3d(4.0, 3.0, 2.5);
  world.add(room);
  world.build();
  const LidarConfig lidar = exact_lidar();
  const Eigen::Isometry3d pose = pose_at(Eigen::Vector3d(0.0, 0.5, 1.2), -0.3);
  const std::vector<Vec3f> points = simulate_scan(world, lidar, pose, 1);
  ASSERT_EQ(static_cast<int>(points.size()),
            lidar.columns * lidar.rows);  // a closed room: every beam hits
  for (const Vec3f& p : points) {
    // Exit distance through the nearest wall, face by face.
    const Eigen::Vector3d direction = pose.linear() * Eigen::Vector3d(p.x, p.y, p.z).normalized();
    const Eigen::Vector3d origin = pose.translation() - room.centre_m;
    double expected = kNoHit;
    for (int axis = 0; axis < 3; ++axis) {
      if (std::abs(direction[axis]) < 1e-12) continue;
      const double wall =
          direction[axis] > 0 ? room.half_extent_m[axis] : -room.half_extent_m[axis];
      expected = std::min(expected, (wall - origin[axis]) / direction[axis]);
    }
    EXPECT_NEAR(Eigen::Vector3d(p.x, p.y, p.z).norm(), expected, 1e-5 * expected);
  }
}

TEST(Simulator, RangesMatchAnalyticDistancesToACylinder) {
  World world;
  Cylinder pole;
  pole.base_centre_m = Eigen::Vector3d(6.0, 1.0, -10.0);
  pole.radius_m = 1.5;
  pole.height_m = 20.0;
  world.add(pole);
  world.build();
  const LidarConfig lidar = exact_lidar(720, 16);
  const Eigen::Isometry3d pose = pose_at(Eigen::Vector3d(0.0, 0.0, 0.0), 0.2);
  const std::vector<Vec3f> points = simulate_scan(world, lidar, pose, 1);
  ASSERT_GT(points.size(), 100u);
  for (const Vec3f& p : points) {
    const Eigen::Vector3d world_point = to_world(pose, p);
    // On the mantle, and the nearer of the two crossings: the one facing the sensor.
    EXPECT_NEAR((world_point - pole.base_centre_m).head<2>().norm(), pole.radius_m, 1e-4);
    const Eigen::Vector2d outward = (world_point - pole.base_centre_m).head<2>();
    EXPECT_LT(outward.dot((world_point - pose.translation()).head<2>()), 0.0);
  }
  // The beam straight at the axis measures the distance to the axis minus the radius.
  const double expected =
      (pole.base_centre_m.head<2>() - pose.translation().head<2>()).norm() - pole.radius_m;
  const Eigen::Vector3d towards = (pose.inverse() * Eigen::Vector3d(6.0, 1.0, 0.0)).normalized();
  EXPECT_NEAR(world.intersect(pose.translation(), pose.linear() * towards), expected, 1e-9);
}

TEST(Simulator, HierarchyFindsTheSameHitsAsTestingEveryPrimitive) {
  const Figure8Path path{FlightConfig()};
  const Site site = build_site(SiteConfig(), path, 3);
  Random random(5);
  int hits = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d origin(random.uniform(-60, 60), random.uniform(-40, 40),
                                 random.uniform(0.5, 6.0));
    const Eigen::Vector3d direction =
        Eigen::Vector3d(random.normal(), random.normal(), random.normal()).normalized();
    double brute = kNoHit;
    for (const Box& b : site.world.boxes())
      brute = std::min(brute, intersect(b, origin, direction));
    for (const Cylinder& c : site.world.cylinders())
      brute = std::min(brute, intersect(c, origin, direction));
    for (const Sphere& s : site.world.spheres())
      brute = std::min(brute, intersect(s, origin, direction));
    for (const Triangle& t : site.world.triangles())
      brute = std::min(brute, intersect(t, origin, direction));
    const double fast = site.world.intersect(origin, direction);
    if (brute == kNoHit) {
      EXPECT_EQ(fast, kNoHit);
    } else {
      ++hits;
      EXPECT_DOUBLE_EQ(fast, brute);
    }
  }
  EXPECT_GT(hits, 1000);
}

TEST(Simulator, FlightHasTheRequestedShapeAndOdometryDriftsAtLeastAsConfigured) {
  const FlightConfig flight;
  const Figure8Path path(flight);
  EXPECT_NEAR(path.length_m(), 400.0, 0.5);
  const std::vector<StampedIsometry> truth = simulate_truth(path, flight);
  EXPECT_EQ(truth.size(), 2001u);  // 200 s at 10 Hz
  EXPECT_NEAR((truth[1].pose.translation() - truth[0].pose.translation()).norm(), 0.2, 0.01);
  // The attitude is continuous from the first pose on: a drone at 2 m/s on this path tilts a few
  // degrees at most, and the first pose like the second.
  for (size_t k = 0; k < truth.size(); ++k) {
    ASSERT_GT(truth[k].pose.linear()(2, 2), std::cos(15.0 * 3.14159265358979323846 / 180.0)) << k;
  }
  EXPECT_GT((truth[0].pose.linear().transpose() * truth[1].pose.linear())(2, 2), 0.9999);
  EXPECT_GT((truth.back().pose.linear().transpose() * truth[truth.size() - 2].pose.linear())(2, 2),
            0.9999);
  for (double minimum_m : {3.0, 6.0}) {
    DriftConfig drift;
    drift.min_final_drift_m = minimum_m;
    const std::vector<StampedIsometry> odometry = simulate_odometry(truth, drift, 11);
    EXPECT_GE(final_drift_m(truth, odometry), minimum_m);
    EXPECT_TRUE(odometry[0].pose.isApprox(truth[0].pose));
    // Drift is in x, y, z and yaw only: roll and pitch stay those of the truth.
    const Eigen::Vector3d truth_up = truth.back().pose.linear().col(2);
    const Eigen::Vector3d odometry_up = odometry.back().pose.linear().col(2);
    EXPECT_NEAR(truth_up.z(), odometry_up.z(), 1e-9);
  }
  // --drift-scale: 0 gives the truth itself; any factor keeps the least final drift.
  const std::vector<StampedIsometry> exact =
      simulate_odometry(truth, DriftConfig().scaled(0.0), 11);
  ASSERT_EQ(exact.size(), truth.size());
  for (size_t k = 0; k < truth.size(); k += 100)
    EXPECT_TRUE(exact[k].pose.isApprox(truth[k].pose, 1e-12)) << k;
  EXPECT_LT(final_drift_m(truth, exact), 1e-9);
  EXPECT_GE(final_drift_m(truth, simulate_odometry(truth, DriftConfig().scaled(0.5), 11)), 3.0);
  EXPECT_THROW(DriftConfig().scaled(-1.0), Error);
}

// Writes the first `scans` scans of the default flight (seed `seed`, a small LiDAR) as a bag and
// returns its bytes.
std::vector<char> simulated_bag_bytes(const std::string& path, uint64_t seed, size_t scans) {
  const FlightConfig flight;
  const Figure8Path path_8(flight);
  const Site site = build_site(SiteConfig(), path_8, seed);
  const std::vector<StampedIsometry> truth = simulate_truth(path_8, flight);
  const std::vector<StampedIsometry> odometry = simulate_odometry(truth, DriftConfig(), seed);
  LidarConfig lidar;
  lidar.columns = 64;
  lidar.rows = 16;
  {
    FlightBagWriter writer(path);
    for (size_t k = 0; k < scans; ++k) {
      writer.write_scan(
          truth[k].stamp_s, truth[k].pose, odometry[k].pose,
          simulate_scan(site.world, lidar, truth[k].pose, stream_seed(seed, 0x5CA7, k)), {});
    }
    writer.close();
  }
  std::ifstream file(path, std::ios::binary);
  return std::vector<char>(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
}

TEST(Simulator, SameSeedGivesAnIdenticalBagAndAnotherSeedAnotherBag) {
  const std::string path = ::testing::TempDir() + "/simulator_test_determinism.bag";
  const std::vector<char> first = simulated_bag_bytes(path, 5, 4);
  const std::vector<char> second = simulated_bag_bytes(path, 5, 4);
  const std::vector<char> other = simulated_bag_bytes(path, 6, 4);
  ASSERT_GT(first.size(), 4096u + 4 * 64 * 16 * 12 / 2);  // header plus at least half the beams
  EXPECT_TRUE(first == second);
  EXPECT_FALSE(first == other);
  std::remove(path.c_str());
}

TEST(Simulator, FlightBagHasTheArcheLayoutAndReadsBackAsWritten) {
  const std::string path = ::testing::TempDir() + "/simulator_test_layout.bag";
  const size_t scans = 3;
  std::vector<Eigen::Isometry3d> truth(scans), odometry(scans);
  std::vector<std::vector<Vec3f>> points(scans);
  {
    FlightBagWriter writer(path);
    for (size_t k = 0; k < scans; ++k) {
      truth[k] = pose_at(Eigen::Vector3d(2.0 * k, 1.0, 3.0), 0.3 * k);
      odometry[k] = pose_at(Eigen::Vector3d(2.0 * k + 0.1 * k, 1.2, 3.0), 0.3 * k + 0.05 * k);
      for (int i = 0; i < 100; ++i) points[k].emplace_back(1.0f + i, 0.5f * i - 20.0f, 0.1f * k);
      writer.write_scan(1000.0 + 0.1 * k, truth[k], odometry[k], points[k], {});
    }
    writer.close();
  }
  const ArcheBagLayout layout;
  io::rosbag::BagReader bag(path);
  EXPECT_EQ(bag.message_count(layout.cloud_topic), scans);
  EXPECT_EQ(bag.message_count("/tf"), scans);
  EXPECT_EQ(bag.message_count("/tf_static"), 1u);
  EXPECT_EQ(bag.message_count(layout.ground_truth_topic), scans);

  // The runner's view: clouds in os1_lidar with the odometry pose of os1_lidar found through
  // odom -> imu -> os1_sensor -> os1_lidar, and the fixes as the reference.
  tools::BagScanSource source(path, tools::BagScanOptions());
  ASSERT_EQ(source.size(), scans);
  ASSERT_EQ(source.reference().size(), scans);
  EXPECT_FALSE(source.reference().has_orientations);
  tools::SourceScan scan;
  for (size_t k = 0; k < scans; ++k) {
    ASSERT_TRUE(source.next(&scan));
    EXPECT_NEAR(scan.stamp_s, 1000.0 + 0.1 * k, 1e-9);
    const Eigen::Isometry3d expected_pose = odometry[k] * T_os1_sensor_os1_lidar();
    EXPECT_TRUE(scan.T_odom_sensor.isApprox(expected_pose, 1e-9)) << "scan " << k;
    ASSERT_EQ(scan.points_sensor_m.size(), points[k].size());
    for (size_t i = 0; i < points[k].size(); ++i) {
      // Same point in the world whichever frame it was written in.
      const Eigen::Vector3d written =
          odometry[k] * Eigen::Vector3d(points[k][i].x, points[k][i].y, points[k][i].z);
      const Eigen::Vector3d read =
          scan.T_odom_sensor * Eigen::Vector3d(scan.points_sensor_m[i].x, scan.points_sensor_m[i].y,
                                               scan.points_sensor_m[i].z);
      ASSERT_LT((written - read).norm(), 1e-4);
    }
    EXPECT_LT((source.reference().poses[k].position_m - truth[k].translation()).norm(), 1e-12);
  }
  EXPECT_FALSE(source.next(&scan));
  EXPECT_EQ(source.dropped(), 0);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace sim
}  // namespace covox

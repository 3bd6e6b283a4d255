// Simulated missions of any length: the figure 8 flown as laps continues the path without a jump
// or a kink, later laps differ from the first, --duration-s sets the length and impossible
// combinations name the option to change, the odometry drift keeps growing with the distance
// flown (or ends the requested percentage of it off), the in-process source hands out exactly
// what the bag route reads (points, point times, the odometry over each sweep, which the bag's tf
// covers), and without the yaw sweep and distortion the flight is the one the single-lap
// simulator made.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "runner/bag_scan_source.h"
#include "cli/command_line.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/rosbag_reader.h"
#include "covoxslam/io/trajectory_io.h"
#include "sim/sim_flight.h"
#include "sim/sim_flight_bag.h"
#include "sim/sim_mission.h"
#include "sim/sim_mission_bag.h"
#include "runner/sim_scan_source.h"

namespace covox {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

SimulationOptions read_options(std::vector<std::string> words) {
  words.insert(words.begin(), "sim_mission_test");
  std::vector<const char*> argv;
  for (const std::string& word : words) argv.push_back(word.c_str());
  tools::CommandLine args(static_cast<int>(argv.size()), argv.data(), "usage: sim_mission_test");
  SimulationOptions options = read_simulation_options(args);
  args.finish();
  return options;
}

Eigen::Vector3d point_at(const Figure8Path& path, double distance_m) {
  const Eigen::Vector2d xy = path.position_m(distance_m);
  return Eigen::Vector3d(xy.x(), xy.y(), path.altitude_m(distance_m));
}

// 64-bit FNV-1a of a file's bytes.
uint64_t file_hash(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  const std::vector<char> bytes((std::istreambuf_iterator<char>(file)),
                                std::istreambuf_iterator<char>());
  uint64_t hash = 0xcbf29ce484222325ull;
  for (const char byte : bytes) {
    hash ^= static_cast<uint8_t>(byte);
    hash *= 0x100000001b3ull;
  }
  return hash;
}

TEST(SimMission, LapsContinueThePathWithoutJumpOrKink) {
  FlightConfig config;
  config.path_length_m = 2000.0;
  const Figure8Path path(config);
  ASSERT_EQ(path.lap_count(), 5u);
  EXPECT_NEAR(path.lap_length_m(), 400.0, 0.01);
  EXPECT_NEAR(path.length_m(), 2000.0, 0.05);
  // The first lap is the single-lap figure 8 of the same lap length, bit for bit.
  FlightConfig one_lap = config;
  one_lap.path_length_m = path.lap_length_m();
  const Figure8Path single(one_lap);
  for (double s = 0.0; s <= single.length_m(); s += 0.7) {
    ASSERT_EQ(path.position_m(s), single.position_m(s)) << s;
    ASSERT_EQ(path.direction(s), single.direction(s)) << s;
    ASSERT_EQ(path.altitude_m(s), single.altitude_m(s)) << s;
  }
  // Along the whole flight in steps of 5 cm of the nominal path: each step moves the drone by
  // about its length (no jump: a lateral offset of up to 1 m on the inside or outside of the
  // tightest turn, of about 9 m radius, shortens or lengthens it by up to 11 %; the altitude
  // changes add a little) and the direction of travel turns by less than a degree (no kink).
  const double step_m = 0.05;
  for (double s = step_m; s <= path.length_m(); s += step_m) {
    const double moved = (point_at(path, s) - point_at(path, s - step_m)).norm();
    ASSERT_GT(moved, 0.85 * step_m) << s;
    ASSERT_LT(moved, 1.15 * step_m) << s;
    ASSERT_GT(path.direction(s).dot(path.direction(s - step_m)), std::cos(kPi / 180.0)) << s;
  }
  // At and around every lap boundary: continuous, and the direction is the path's own tangent.
  for (size_t lap = 1; lap < path.lap_count(); ++lap) {
    const double boundary = lap * path.lap_length_m();
    for (const double s : {boundary - 1e-6, boundary, boundary + 1e-6, boundary + 3.0}) {
      const Eigen::Vector2d chord = path.position_m(s + 0.25) - path.position_m(s - 0.25);
      EXPECT_GT(path.direction(s).dot(chord.normalized()), 0.9999) << lap << " " << s;
    }
    EXPECT_LT((path.position_m(boundary - 1e-6) - path.position_m(boundary + 1e-6)).norm(), 1e-5);
    // Every lap starts at the crossing, shifted by the previous lap's offset.
    EXPECT_LT(path.position_m(boundary).norm(), config.lap_lateral_offset_m + 1e-9);
  }
}

TEST(SimMission, LaterLapsAreShiftedALittleAndStayInTheDoorsAtThePassage) {
  FlightConfig config;
  config.path_length_m = 2000.0;
  const Figure8Path path(config);
  const double lap_m = path.lap_length_m();
  // A quarter lap from the crossing the nominal path is at the passage centre (x = A, y = 0).
  const double passage_s = 0.25 * lap_m;
  ASSERT_LT((path.position_m(passage_s) - path.passage_centre_m()).norm(), 0.05);
  double largest_shift = 0.0;
  for (size_t lap = 1; lap < path.lap_count(); ++lap) {
    for (double s = 0.0; s < lap_m; s += 2.0) {
      const Eigen::Vector3d shift = point_at(path, lap * lap_m + s) - point_at(path, s);
      ASSERT_LE(shift.head<2>().norm(), config.lap_lateral_offset_m + 1e-9) << lap << " " << s;
      ASSERT_LE(std::abs(shift.z()), config.lap_altitude_offset_m + 1e-9) << lap << " " << s;
      largest_shift = std::max(largest_shift, shift.norm());
    }
    // A quarter of the offsets at the passage: inside the 1.8 m doors and under their lintels.
    const Eigen::Vector3d at_passage =
        point_at(path, lap * lap_m + passage_s) - point_at(path, passage_s);
    EXPECT_LE(at_passage.head<2>().norm(), 0.25 * config.lap_lateral_offset_m + 1e-9);
    EXPECT_LE(std::abs(at_passage.z()), 0.25 * config.lap_altitude_offset_m + 1e-9);
  }
  EXPECT_GT(largest_shift, 0.3);  // revisits are not exact repeats
  // Another seed shifts the laps differently.
  FlightConfig other = config;
  other.variation_seed = 2;
  const Figure8Path other_path(other);
  EXPECT_GT((other_path.position_m(1.5 * lap_m) - path.position_m(1.5 * lap_m)).norm(), 1e-3);
}

TEST(SimMission, DurationSetsTheLengthAndImpossibleFlightsNameTheOptionToChange) {
  const SimulationOptions options = read_options({"--duration-s", "600", "--speed-m-per-s", "1.5"});
  EXPECT_DOUBLE_EQ(options.flight.path_length_m, 900.0);
  const Figure8Path path(options.flight);
  const std::vector<StampedIsometry> truth = simulate_truth(path, options.flight);
  ASSERT_EQ(truth.size(), 6001u);  // 600 s at 10 Hz, both ends
  EXPECT_NEAR(truth.back().stamp_s - truth.front().stamp_s, 600.0, 1e-6);
  EXPECT_EQ(read_options({"--path-length-m", "1234"}).flight.path_length_m, 1234.0);
  EXPECT_EQ(read_options({"--lobe-half-length-m", "30"}).flight.lobe_half_length_m, 30.0);

  EXPECT_EXIT(read_options({"--duration-s", "60", "--path-length-m", "100"}),
              ::testing::ExitedWithCode(2), "--path-length-m or --duration-s, not both");
  EXPECT_EXIT(read_options({"--drift-percent", "1", "--min-drift-m", "2"}),
              ::testing::ExitedWithCode(2), "not both");
  EXPECT_EXIT(read_options({"--duration-s", "-5"}), ::testing::ExitedWithCode(2), "--duration-s");

  // A lap that a figure 8 of this half length cannot fly: the message names the options.
  FlightConfig too_long_lap;
  too_long_lap.lap_length_m = 1000.0;
  too_long_lap.path_length_m = 3000.0;
  try {
    const Figure8Path impossible(too_long_lap);
    ADD_FAILURE() << "a 1000 m lap with 55 m lobes was accepted";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("--lobe-half-length-m"), std::string::npos);
    EXPECT_NE(std::string(error.what()).find("--lap-length-m"), std::string::npos);
  }
  // A path shorter than any figure 8 of these lobes: the start of one default-sized lap.
  FlightConfig too_short;
  too_short.path_length_m = 100.0;
  const Figure8Path short_path(too_short);
  EXPECT_EQ(short_path.lap_count(), 1u);
  EXPECT_DOUBLE_EQ(short_path.length_m(), 100.0);
  EXPECT_NEAR(short_path.lap_length_m(), FlightConfig().path_length_m, 0.01);
  // Given lap length: 2.5 laps, the last one partial.
  FlightConfig partial;
  partial.lap_length_m = 300.0;
  partial.path_length_m = 750.0;
  const Figure8Path partial_path(partial);
  EXPECT_EQ(partial_path.lap_count(), 3u);
  EXPECT_DOUBLE_EQ(partial_path.length_m(), 750.0);
  EXPECT_NEAR(partial_path.lap_length_m(), 300.0, 0.01);
}

TEST(SimMission, OdometryDriftKeepsGrowingWithTheDistanceFlown) {
  FlightConfig config;
  config.path_length_m = 4000.0;  // 10 laps, 2000 s
  config.lap_length_m = 400.0;
  const Figure8Path path(config);
  ASSERT_EQ(path.lap_count(), 10u);
  const std::vector<StampedIsometry> truth = simulate_truth(path, config);
  const std::vector<StampedIsometry> odometry = simulate_odometry(truth, DriftConfig(), 3);
  // The drift where every lap ends (back at the crossing point, so the lap's shape does not
  // matter), averaged over the first and the last three laps.
  const size_t scans_per_lap = (truth.size() - 1) / path.lap_count();
  const auto drift_at_lap_end = [&](size_t lap) {
    const size_t k = (lap + 1) * scans_per_lap;
    return (odometry.at(k).pose.translation() - truth.at(k).pose.translation()).norm();
  };
  const double early = drift_at_lap_end(0) + drift_at_lap_end(1) + drift_at_lap_end(2);
  const double late = drift_at_lap_end(7) + drift_at_lap_end(8) + drift_at_lap_end(9);
  EXPECT_GT(late, 2.0 * early);
  EXPECT_GT(final_drift_m(truth, odometry), 10.0);

  // --drift-percent: the odometry ends that share of the distance flown off.
  double distance_m = 0.0;
  for (size_t k = 1; k < truth.size(); ++k)
    distance_m += (truth[k].pose.translation() - truth[k - 1].pose.translation()).norm();
  EXPECT_NEAR(distance_m, 4000.0, 5.0);
  for (const double percent : {0.5, 2.0}) {
    DriftConfig drift;
    drift.final_drift_percent = percent;
    const double final_m = final_drift_m(truth, simulate_odometry(truth, drift, 3));
    EXPECT_NEAR(final_m, 0.01 * percent * distance_m, 0.0101 * 0.01 * percent * distance_m);
  }
  // --drift-scale 0 leaves the odometry equal to the truth, however long the flight.
  DriftConfig with_percent;
  with_percent.final_drift_percent = 1.0;
  const std::vector<StampedIsometry> exact = simulate_odometry(truth, with_percent.scaled(0.0), 3);
  for (size_t k = 0; k < truth.size(); k += 97)
    ASSERT_TRUE(exact[k].pose.isApprox(truth[k].pose, 1e-12)) << k;
}

// The odometry samples (tf odom -> imu, as T_odom_os1_lidar) and the clouds of a flight bag.
struct BagContents {
  std::vector<double> tf_stamps_s, tf_recorded_s;
  std::vector<Eigen::Isometry3d> T_odom_lidar;
  std::vector<double> cloud_stamps_s, cloud_recorded_s;
  std::vector<io::rosbag::PointCloud2Message> clouds;
};

BagContents read_bag(const std::string& path) {
  namespace rb = io::rosbag;
  rb::BagReader bag(path);
  BagContents contents;
  const Eigen::Isometry3d T_imu_lidar = T_imu_os1_sensor() * T_os1_sensor_os1_lidar();
  for (const rb::IndexEntry& entry : bag.index({"/tf"})) {
    const rb::BagMessage message = bag.read(entry);
    const rb::TfMessage tf = rb::parse_tf_message(message.data.data(), message.data.size(), "tf");
    EXPECT_EQ(tf.transforms.size(), 1u);
    contents.tf_stamps_s.push_back(tf.transforms[0].header.stamp.to_seconds());
    contents.tf_recorded_s.push_back(entry.time.to_seconds());
    contents.T_odom_lidar.push_back(tf.transforms[0].T_parent_child * T_imu_lidar);
  }
  for (const rb::IndexEntry& entry : bag.index({ArcheBagLayout().cloud_topic})) {
    const rb::BagMessage message = bag.read(entry);
    contents.clouds.push_back(
        rb::parse_point_cloud2(message.data.data(), message.data.size(), "cloud"));
    contents.cloud_stamps_s.push_back(contents.clouds.back().header.stamp.to_seconds());
    contents.cloud_recorded_s.push_back(entry.time.to_seconds());
  }
  return contents;
}

// The values of the uint32 field `t` of the cloud's points at least `min_range_m` from the
// sensor (as the scan sources keep them); fails the test when the cloud has no such field.
std::vector<uint32_t> point_times_ns(const io::rosbag::PointCloud2Message& cloud,
                                     double min_range_m) {
  const io::rosbag::PointField* field = nullptr;
  for (const io::rosbag::PointField& f : cloud.fields) {
    if (f.name == "t") field = &f;
  }
  std::vector<uint32_t> times;
  if (field == nullptr) {
    ADD_FAILURE() << "the cloud has no field t";
    return times;
  }
  EXPECT_EQ(field->datatype, io::kUint32);
  EXPECT_EQ(field->offset, 12u);  // after x, y and z
  for (uint32_t i = 0; i < cloud.width; ++i) {
    const uint8_t* point = cloud.data.data() + size_t(i) * cloud.point_step;
    Eigen::Vector3f p;
    std::memcpy(p.data(), point, 12);
    if (p.squaredNorm() < static_cast<float>(min_range_m * min_range_m)) continue;
    uint32_t t = 0;
    std::memcpy(&t, point + field->offset, 4);
    times.push_back(t);
  }
  return times;
}

// The bag's odometry at `stamp_s` from its tf samples, linearly between the two around it (as a
// tf lookup interpolates); fails the test when the samples do not cover the stamp.
Eigen::Isometry3d interpolated_odometry(const BagContents& bag, double stamp_s) {
  const auto after = std::lower_bound(bag.tf_stamps_s.begin(), bag.tf_stamps_s.end(), stamp_s);
  if (after == bag.tf_stamps_s.end()) {
    ADD_FAILURE() << "no tf sample at or after " << stamp_s;
    return Eigen::Isometry3d::Identity();
  }
  const size_t j = static_cast<size_t>(after - bag.tf_stamps_s.begin());
  if (j == 0) return bag.T_odom_lidar[0];
  const double fraction =
      (stamp_s - bag.tf_stamps_s[j - 1]) / (bag.tf_stamps_s[j] - bag.tf_stamps_s[j - 1]);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = (1.0 - fraction) * bag.T_odom_lidar[j - 1].translation() +
                    fraction * bag.T_odom_lidar[j].translation();
  T.linear() = Eigen::Quaterniond(bag.T_odom_lidar[j - 1].linear())
                   .slerp(fraction, Eigen::Quaterniond(bag.T_odom_lidar[j].linear()))
                   .toRotationMatrix();
  return T;
}

// Writes the first `scans` scans of `mission` as simulate_flight does.
void write_bag(const std::string& path, const SimulatedMission& mission, size_t scans) {
  FlightBagWriter writer(path);
  for (size_t k = 0; k < scans; ++k) write_mission_scan(&writer, mission, k, mission.scan(k));
  writer.close();
}

// The bag's tf covers every sweep: a sample at each cloud's stamp and samples up to the end of
// its sweep, every 10 ms (100 Hz), all recorded before the cloud.
void expect_tf_covers_every_sweep(const BagContents& bag, double sweep_period_s) {
  ASSERT_FALSE(bag.tf_stamps_s.empty());
  for (size_t j = 1; j < bag.tf_stamps_s.size(); ++j)
    ASSERT_NEAR(bag.tf_stamps_s[j] - bag.tf_stamps_s[j - 1], 0.01, 1e-6) << j;
  for (size_t k = 0; k < bag.clouds.size(); ++k) {
    const double stamp_s = bag.cloud_stamps_s[k];
    const auto at_stamp = std::find(bag.tf_stamps_s.begin(), bag.tf_stamps_s.end(), stamp_s);
    ASSERT_TRUE(at_stamp != bag.tf_stamps_s.end()) << "no tf at the stamp of cloud " << k;
    const double end_s = stamp_s + sweep_period_s;
    const auto covering =
        std::lower_bound(bag.tf_stamps_s.begin(), bag.tf_stamps_s.end(), end_s - 1e-9);
    ASSERT_TRUE(covering != bag.tf_stamps_s.end()) << "the tf ends within sweep " << k;
    const size_t j = static_cast<size_t>(covering - bag.tf_stamps_s.begin());
    EXPECT_LE(bag.tf_recorded_s[j], bag.cloud_recorded_s[k] + 1e-9) << k;
    EXPECT_NEAR(bag.cloud_recorded_s[k], end_s, 1e-6) << k;
  }
}

TEST(SimMission, InProcessScansEqualTheBagRoute) {
  // The start of a two-lap flight on a small site, distorted and instantaneous.
  for (const bool instantaneous : {false, true}) {
    std::vector<std::string> words = {"--seed",
                                      "7",
                                      "--columns",
                                      "64",
                                      "--rows",
                                      "16",
                                      "--lobe-half-length-m",
                                      "20",
                                      "--lap-length-m",
                                      "120",
                                      "--path-length-m",
                                      "240"};
    if (instantaneous) words.push_back("--instantaneous-scan");
    const SimulationOptions options = read_options(words);
    EXPECT_EQ(options.lidar.instantaneous, instantaneous);
    const size_t scans = 4;
    const SimulatedMission mission(options, scans);
    ASSERT_EQ(mission.size(), scans);
    const std::string bag_path = ::testing::TempDir() + "/sim_mission_test.bag";
    write_bag(bag_path, mission, scans);
    const BagContents contents = read_bag(bag_path);
    expect_tf_covers_every_sweep(contents, mission.sweep_period_s());
    tools::BagScanOptions bag_options;
    bag_options.min_range_m = 0.5;
    tools::BagScanSource from_bag(bag_path, bag_options);
    tools::SimScanSource in_process(options, bag_options.min_range_m, scans);
    ASSERT_EQ(in_process.size(), from_bag.size());
    EXPECT_NEAR(in_process.duration_s(), from_bag.duration_s(), 1e-6);
    EXPECT_EQ(in_process.reference_kind(), tools::ReferenceKind::kGroundTruth);
    ASSERT_EQ(in_process.reference().size(), from_bag.reference().size());
    tools::SourceScan a, b;
    for (size_t k = 0; k < scans; ++k) {
      ASSERT_TRUE(in_process.next(&a));
      ASSERT_TRUE(from_bag.next(&b));
      EXPECT_NEAR(a.stamp_s, b.stamp_s, 1e-8);
      EXPECT_TRUE(a.T_odom_sensor.isApprox(b.T_odom_sensor, 1e-9)) << k;
      ASSERT_EQ(a.points_sensor_m.size(), b.points_sensor_m.size()) << k;
      ASSERT_GT(a.points_sensor_m.size(), 100u);
      for (size_t i = 0; i < a.points_sensor_m.size(); ++i) {
        ASSERT_EQ(a.points_sensor_m[i].x, b.points_sensor_m[i].x) << k << " " << i;
        ASSERT_EQ(a.points_sensor_m[i].y, b.points_sensor_m[i].y) << k << " " << i;
        ASSERT_EQ(a.points_sensor_m[i].z, b.points_sensor_m[i].z) << k << " " << i;
      }
      EXPECT_LT(
          (in_process.reference().poses[k].position_m - from_bag.reference().poses[k].position_m)
              .norm(),
          1e-12);
      if (instantaneous) {
        // No times: the points are used as they are.
        EXPECT_TRUE(a.point_times_s.empty());
        EXPECT_FALSE(a.sweep.known);
        for (const io::rosbag::PointField& field : contents.clouds[k].fields)
          EXPECT_NE(field.name, "t");
        continue;
      }
      // The times are the bag's field t, point for point, in seconds.
      const std::vector<uint32_t> times_ns = point_times_ns(contents.clouds[k], 0.5);
      ASSERT_EQ(a.point_times_s.size(), a.points_sensor_m.size());
      ASSERT_EQ(times_ns.size(), a.point_times_s.size());
      for (size_t i = 0; i < times_ns.size(); ++i)
        ASSERT_EQ(a.point_times_s[i], static_cast<float>(times_ns[i] * 1e-9)) << k << " " << i;
      if (!b.point_times_s.empty()) {
        EXPECT_TRUE(a.point_times_s == b.point_times_s) << k;
      }
      // The sweep: the first and last point time, the odometry there as the bag's tf gives it.
      const auto [first, last] = std::minmax_element(times_ns.begin(), times_ns.end());
      ASSERT_TRUE(a.sweep.known);
      EXPECT_EQ(a.sweep.begin_s, static_cast<float>(*first * 1e-9));
      EXPECT_EQ(a.sweep.end_s, static_cast<float>(*last * 1e-9));
      EXPECT_GT(a.sweep.end_s, 0.09);  // a 64-column sweep's last column fires at 98.4 ms
      EXPECT_LT(a.sweep.end_s, 0.1);
      // The odometry there is the bag's tf interpolated between its 10 ms samples (this test's
      // own interpolation of them; runner/test/sim_bag_route_test.cpp compares the in-process
      // source with the bag reader's bit for bit).
      const auto expect_close = [k](const Eigen::Isometry3d& pose, const Eigen::Isometry3d& other) {
        EXPECT_LT((pose.translation() - other.translation()).norm(), 1e-4) << k;
        EXPECT_LT(Eigen::AngleAxisd(pose.linear().transpose() * other.linear()).angle(), 1e-5) << k;
      };
      expect_close(a.sweep.T_odom_sensor_begin,
                   interpolated_odometry(contents, a.stamp_s + a.sweep.begin_s));
      expect_close(a.sweep.T_odom_sensor_end,
                   interpolated_odometry(contents, a.stamp_s + a.sweep.end_s));
    }
    EXPECT_FALSE(in_process.next(&a));
    EXPECT_FALSE(from_bag.next(&b));
    std::remove(bag_path.c_str());
  }
}

// Without the yaw sweep and with the instantaneous LiDAR, the default flight is the single-lap
// simulator's, byte for byte: the hashes are those of the files simulate_flight wrote before
// flights had laps (full trajectories of the default options; the bag, one tf per scan, and world
// of `--columns 64 --rows 16 --max-scans 3`). The bag of today's default (distorted scans with
// their times, tf at 100 Hz) is pinned by its own hash, so that it changes only on purpose.
TEST(SimMission, DefaultFlightIsTheSingleLapSimulatorsFlight) {
  const std::string folder = ::testing::TempDir();
  {
    const SimulatedMission mission(read_options({"--yaw-sweep-amplitude-deg", "0"}));
    ASSERT_EQ(mission.size(), 2001u);
    std::vector<StampedIsometry> truth = mission.truth(), odometry = mission.odometry();
    for (size_t k = 0; k < truth.size(); ++k) {
      truth[k].pose = truth[k].pose * T_os1_sensor_os1_lidar();
      odometry[k].pose = odometry[k].pose * T_os1_sensor_os1_lidar();
    }
    io::write_tum_trajectory(folder + "/sim_default_truth.tum", to_trajectory(truth));
    io::write_tum_trajectory(folder + "/sim_default_odometry.tum", to_trajectory(odometry));
  }
  EXPECT_EQ(file_hash(folder + "/sim_default_truth.tum"), 0xde4721be30f12008ull);
  EXPECT_EQ(file_hash(folder + "/sim_default_odometry.tum"), 0xd4c7b9ac00733c02ull);

  const SimulatedMission small(
      read_options({"--columns", "64", "--rows", "16", "--yaw-sweep-amplitude-deg", "0",
                    "--instantaneous-scan"}),
      3);
  io::write_mesh_ply(folder + "/sim_default_world.ply", small.site().world.to_mesh());
  {
    FlightBagWriter writer(folder + "/sim_default.bag");
    for (size_t k = 0; k < small.size(); ++k) {
      writer.write_scan(small.truth()[k].stamp_s, small.truth()[k].pose, small.odometry()[k].pose,
                        small.scan(k).points_sensor_m, {});
    }
    writer.close();
  }
  EXPECT_EQ(file_hash(folder + "/sim_default_world.ply"), 0x697d36b781e30ebfull);
  EXPECT_EQ(file_hash(folder + "/sim_default.bag"), 0x9abc6e861aff5288ull);
  write_bag(folder + "/sim_distorted.bag",
            SimulatedMission(read_options({"--columns", "64", "--rows", "16"}), 3), 3);
  EXPECT_EQ(file_hash(folder + "/sim_distorted.bag"), 0x44e68f397ad0927ull);
  for (const char* name : {"sim_default_truth.tum", "sim_default_odometry.tum",
                           "sim_default_world.ply", "sim_default.bag", "sim_distorted.bag"}) {
    std::remove((folder + "/" + name).c_str());
  }
}

}  // namespace
}  // namespace sim
}  // namespace covox

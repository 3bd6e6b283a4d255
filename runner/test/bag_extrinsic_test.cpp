// The sensor extrinsic of a bag run (runner/bag_extrinsic.h, run_slam --extrinsic): a bag
// without the static transform from the robot to its LiDAR, given that transform as the
// extrinsic, yields the same scans (poses and points) and maps the same as the bag that carries
// it on /tf_static; the extrinsic wins over the bag's own tf with a log line naming both; the
// configuration file's `ros` keys give it as the nodelet takes them; bad values are errors naming
// the option or the file and line.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "runner/bag_extrinsic.h"
#include "runner/bag_scan_source.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/io/rosbag_messages.h"
#include "covoxslam/io/rosbag_writer.h"
#include "covoxslam/io/transform_numbers.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "runner/slam_run.h"
#include "support/analytic_scene.h"

namespace covox {
namespace tools {
namespace {

namespace fs = std::filesystem;
namespace rb = io::rosbag;

constexpr size_t kScans = 16;
// The ARCHE layout: the LiDAR 8 cm above and 3 cm ahead of the IMU, its os1_lidar frame turned
// 180 degrees about z from os1_sensor. Composed: imu -> os1_lidar.
const char kExtrinsicText[] = "0.03 0 0.08 0 0 1 0";

Eigen::Isometry3d transform(const Eigen::Vector3d& translation, double yaw_rad) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = translation;
  return T;
}

const Eigen::Isometry3d kImuSensor = transform(Eigen::Vector3d(0.03, 0.0, 0.08), 0.0);
// The 180 degree yaw exactly (cos = -1, sin = 0), as the bag's quaternion (0, 0, 1, 0) gives it:
// then the tf chain and the extrinsic compose the same numbers, and the maps can be compared bit
// for bit.
Eigen::Isometry3d exact_half_turn() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Vector3d(-1.0, -1.0, 1.0).asDiagonal();
  return T;
}
const Eigen::Isometry3d kSensorLidar = exact_half_turn();

rb::TransformStamped stamped(const std::string& parent, const std::string& child, rb::RosTime time,
                             const Eigen::Isometry3d& T) {
  rb::TransformStamped transform;
  transform.header.stamp = time;
  transform.header.frame_id = parent;
  transform.child_frame_id = child;
  transform.T_parent_child = T;
  return transform;
}

// The robot flies through a room (odometry tf odom -> imu), its LiDAR scanning the walls; with
// `with_static` the bag carries imu -> os1_sensor -> os1_lidar on /tf_static.
std::vector<Eigen::Isometry3d> write_room_bag(const std::string& path, bool with_static) {
  testing_support::AnalyticScene room;
  room.shape = testing_support::Shape::kBox;
  room.center = Eigen::Vector3d(1.0, 0.5, 1.0);
  room.half_extent = Eigen::Vector3d(7.0, 4.5, 2.5);
  rb::BagWriter bag(path);
  const uint32_t statics = bag.add_connection("/tf_static", rb::tf_message_type(), true);
  const uint32_t tf = bag.add_connection("/tf", rb::tf_message_type());
  const uint32_t clouds = bag.add_connection("/points", rb::point_cloud2_type());
  std::vector<Eigen::Isometry3d> T_odom_imu;
  for (size_t k = 0; k < kScans; ++k) {
    const rb::RosTime time = rb::RosTime::from_seconds(50.0 + 0.1 * k);
    if (k == 0 && with_static) {
      rb::TfMessage lever;
      lever.transforms = {stamped("imu", "os1_sensor", time, kImuSensor),
                          stamped("os1_sensor", "os1_lidar", time, kSensorLidar)};
      bag.write(statics, time, rb::serialize(lever));
    }
    T_odom_imu.push_back(transform(Eigen::Vector3d(0.08 * k, 0.02 * k, 1.0), 0.015 * k));
    rb::TfMessage odometry;
    odometry.transforms = {stamped("odom", "imu", time, T_odom_imu.back())};
    bag.write(tf, time, rb::serialize(odometry));
    const Eigen::Isometry3d T_world_lidar = T_odom_imu.back() * kImuSensor * kSensorLidar;
    std::vector<Eigen::Vector3f> points;
    for (const Vec3f& p : testing_support::simulate_lidar(room, T_world_lidar, 360, 16, 30.0, 20.0))
      points.emplace_back(p.x, p.y, p.z);
    rb::Header header;
    header.seq = static_cast<uint32_t>(k);
    header.stamp = time;
    header.frame_id = "os1_lidar";
    bag.write(clouds, time, rb::serialize(rb::make_point_cloud2(header, points)));
  }
  bag.close();
  return T_odom_imu;
}

BagScanOptions room_options() {
  BagScanOptions options;
  options.cloud_topic = "/points";
  options.reference_topic.clear();
  return options;
}

std::vector<SourceScan> read_scans(BagScanSource& source) {
  std::vector<SourceScan> scans;
  SourceScan scan;
  while (source.next(&scan)) scans.push_back(scan);
  return scans;
}

class BagExtrinsic : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // One folder per process: CTest runs each test in its own process, several at once.
    folder_ = new fs::path(fs::path(::testing::TempDir()) /
                           ("bag_extrinsic_" + std::to_string(::getpid())));
    fs::create_directories(*folder_);
    T_odom_imu_ = new std::vector<Eigen::Isometry3d>(write_room_bag(with_static(), true));
    write_room_bag(without_static(), false);
  }
  static void TearDownTestSuite() {
    fs::remove_all(*folder_);
    delete folder_;
    delete T_odom_imu_;
  }
  static std::string with_static() { return (*folder_ / "with_static.bag").string(); }
  static std::string without_static() { return (*folder_ / "without_static.bag").string(); }
  static std::string write_config(const std::string& name, const std::string& text) {
    const std::string path = (*folder_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  static fs::path* folder_;
  static std::vector<Eigen::Isometry3d>* T_odom_imu_;
};
fs::path* BagExtrinsic::folder_ = nullptr;
std::vector<Eigen::Isometry3d>* BagExtrinsic::T_odom_imu_ = nullptr;

TEST_F(BagExtrinsic, BagWithoutTheStaticTransformGivesTheSameScansWithTheExtrinsic) {
  BagScanSource with_tf(with_static(), room_options());
  const std::vector<SourceScan> reference = read_scans(with_tf);
  ASSERT_EQ(reference.size(), kScans);
  for (size_t k = 0; k < kScans; ++k) {
    // The independent check of the tf chain: the poses the bag was written from.
    EXPECT_TRUE(
        reference[k].T_odom_sensor.isApprox((*T_odom_imu_)[k] * kImuSensor * kSensorLidar, 1e-12));
  }

  // Without the static transform and without an extrinsic no cloud has a pose.
  BagScanSource lost(without_static(), room_options());
  EXPECT_TRUE(read_scans(lost).empty());
  EXPECT_EQ(lost.dropped(), static_cast<int64_t>(kScans));

  BagScanOptions options = room_options();
  resolve_bag_extrinsic({}, "imu", kExtrinsicText, &options);
  BagScanSource given(without_static(), options);
  const std::vector<SourceScan> scans = read_scans(given);
  ASSERT_EQ(scans.size(), kScans);
  for (size_t k = 0; k < kScans; ++k) {
    EXPECT_EQ(scans[k].stamp_s, reference[k].stamp_s);
    EXPECT_EQ(scans[k].T_odom_sensor.matrix(), reference[k].T_odom_sensor.matrix()) << k;
    ASSERT_EQ(scans[k].points_sensor_m.size(), reference[k].points_sensor_m.size());
    for (size_t i = 0; i < scans[k].points_sensor_m.size(); ++i) {
      ASSERT_EQ(scans[k].points_sensor_m[i].x, reference[k].points_sensor_m[i].x);
      ASSERT_EQ(scans[k].points_sensor_m[i].z, reference[k].points_sensor_m[i].z);
    }
  }
  EXPECT_NE(given.describe().find("extrinsic imu -> sensor from --extrinsic"), std::string::npos)
      << given.describe();
}

TEST_F(BagExtrinsic, BagWithoutTheStaticTransformMapsTheSameWithTheExtrinsic) {
  pipeline::SlamConfig config = pipeline::load_preset("arche");
  config.submaps.interval_s = 0.5;  // several submaps: registration and the pose graph run
  SlamRunOptions run;
  run.progress_bar = false;
  BagScanSource with_tf(with_static(), room_options());
  const SlamRunResult reference = run_slam_system(with_tf, config, run);
  BagScanOptions options = room_options();
  resolve_bag_extrinsic({}, "imu", kExtrinsicText, &options);
  BagScanSource given(without_static(), options);
  const SlamRunResult result = run_slam_system(given, config, run);
  EXPECT_EQ(reference.counters.scans_integrated, static_cast<int64_t>(kScans));
  EXPECT_EQ(result.counters.scans_integrated, static_cast<int64_t>(kScans));
  ASSERT_GE(reference.submaps.size(), 2u);
  EXPECT_EQ(result.submaps.size(), reference.submaps.size());
  EXPECT_EQ(result.map_blocks, reference.map_blocks);
  EXPECT_EQ(result.mesh.triangle_count(), reference.mesh.triangle_count());
  ASSERT_EQ(result.corrected.size(), reference.corrected.size());
  for (size_t k = 0; k < result.corrected.size(); ++k) {
    EXPECT_EQ(result.corrected.poses[k].position_m, reference.corrected.poses[k].position_m) << k;
    EXPECT_EQ(result.corrected.poses[k].orientation.coeffs(),
              reference.corrected.poses[k].orientation.coeffs())
        << k;
  }
}

TEST_F(BagExtrinsic, GivenExtrinsicWinsOverTheBagsTfWithALogLine) {
  std::vector<std::string> lines;
  set_log_sink([&lines](LogLevel, const std::string& line) { lines.push_back(line); });
  BagScanOptions options = room_options();
  resolve_bag_extrinsic({}, "imu", "0 0 0 0 0 0 1", &options);  // the identity, not the bag's
  BagScanSource source(with_static(), options);
  const std::vector<SourceScan> scans = read_scans(source);
  set_log_sink(
      [](LogLevel, const std::string& line) { std::cerr << "[covoxslam] " << line << std::endl; });
  ASSERT_EQ(scans.size(), kScans);
  for (size_t k = 0; k < kScans; ++k)
    EXPECT_TRUE(scans[k].T_odom_sensor.isApprox((*T_odom_imu_)[k], 1e-12)) << k;
  ASSERT_EQ(lines.size(), 1u);  // once, at the first scan
  EXPECT_NE(lines[0].find("its tf also has imu -> os1_lidar (0.030000 0.000000 0.080000 0.000000 "
                          "0.000000 1.000000 0.000000); the given extrinsic wins"),
            std::string::npos)
      << lines[0];
}

TEST_F(BagExtrinsic, ConfigurationFileGivesItAsTheNodeletTakesIt) {
  const std::string uses_tf = write_config("uses_tf.yaml",
                                           "ros:\n"
                                           "  base_frame: /imu\n"
                                           "  T_base_sensor: [1, 2, 3, 0, 0, 0, 1]\n");
  const std::string given = write_config("given.yaml",
                                         "ros:\n"
                                         "  use_tf_for_extrinsic: false\n"
                                         "  T_base_sensor: [0.03, 0, 0.08, 0, 0, 1, 0]\n");
  // T_base_sensor alone is not used while the nodelet would take tf (use_tf_for_extrinsic).
  BagScanOptions options = room_options();
  resolve_bag_extrinsic({uses_tf}, "", "", &options);
  EXPECT_EQ(options.base_frame, "imu");
  EXPECT_FALSE(options.T_base_sensor.has_value());
  // A later file's keys win over an earlier file's.
  resolve_bag_extrinsic({uses_tf, given}, "", "", &options);
  ASSERT_TRUE(options.T_base_sensor.has_value());
  EXPECT_TRUE(options.T_base_sensor->isApprox(kImuSensor * kSensorLidar, 1e-12));
  EXPECT_NE(options.extrinsic_origin.find("given.yaml:3"), std::string::npos)
      << options.extrinsic_origin;
  BagScanSource source(without_static(), options);
  EXPECT_EQ(read_scans(source).size(), kScans);
  // The command line wins over both files.
  options = room_options();
  resolve_bag_extrinsic({uses_tf, given}, "odom", "0 0 1 0 0 0 1", &options);
  EXPECT_EQ(options.base_frame, "odom");
  EXPECT_EQ(options.extrinsic_origin, "--extrinsic");
  EXPECT_TRUE(options.T_base_sensor->translation().isApprox(Eigen::Vector3d(0, 0, 1)));
  // The shipped ARCHE presets take the transform from tf, with the odometry's imu frame.
  options = room_options();
  resolve_bag_extrinsic({pipeline::preset_path("arche")}, "", "", &options);
  EXPECT_EQ(options.base_frame, "imu");
  EXPECT_FALSE(options.T_base_sensor.has_value());
}

TEST_F(BagExtrinsic, BadValuesAreErrorsNamingTheirSource) {
  const auto message_of = [](const std::vector<std::string>& files, const std::string& extrinsic) {
    BagScanOptions options;
    try {
      resolve_bag_extrinsic(files, "", extrinsic, &options);
    } catch (const Error& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message_of({}, "1 2 3").find("--extrinsic: expected 7 numbers"), std::string::npos);
  EXPECT_NE(message_of({}, "0 0 0 0 0 0 2").find("--extrinsic: the quaternion"), std::string::npos);
  EXPECT_NE(message_of({}, "0 0 0 0 0 zero 1").find("--extrinsic: 'zero'"), std::string::npos);
  const std::string flag = write_config("bad_flag.yaml", "ros:\n  use_tf_for_extrinsic: no\n");
  EXPECT_NE(message_of({flag}, "").find("bad_flag.yaml:2: parameter 'ros.use_tf_for_extrinsic'"),
            std::string::npos)
      << message_of({flag}, "");
  const std::string matrix = write_config("bad_matrix.yaml",
                                          "ros:\n  use_tf_for_extrinsic: false\n"
                                          "  T_base_sensor: [2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, "
                                          "0, 0, 0, 1]\n");
  EXPECT_NE(message_of({matrix}, "")
                .find("bad_matrix.yaml:3: parameter 'ros.T_base_sensor': "
                      "the 4x4 matrix is not a rigid transform"),
            std::string::npos)
      << message_of({matrix}, "");
}

TEST(TransformNumbers, TextFormsGiveTheSameTransform) {
  const Eigen::Isometry3d expected = kImuSensor * kSensorLidar;
  for (const char* text :
       {"0.03 0 0.08 0 0 1 0", "0.03,0,0.08,0,0,1,0", "[0.03, 0, 0.08, 0, 0, 1, 0]",
        " 0.03, 0, 0.08 , 0, 0, 1, 0 ", "-1 0 0 0.03  0 -1 0 0  0 0 1 0.08  0 0 0 1"}) {
    EXPECT_TRUE(io::transform_from_text(text, "test").isApprox(expected, 1e-12)) << text;
  }
  EXPECT_EQ(io::transform_to_text(expected),
            "0.030000 0.000000 0.080000 0.000000 0.000000 "
            "1.000000 0.000000");
  EXPECT_THROW(io::transform_from_text("", "test"), Error);
  EXPECT_THROW(io::transform_from_text("0 0 0 0 0 0 nan", "test"), Error);
}

}  // namespace
}  // namespace tools
}  // namespace covox

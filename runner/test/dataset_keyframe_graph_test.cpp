// LiDAR keyframe graphs (the lidar-scans dumps: NNNNNN/points.bin and graph.txt) read as a scan
// source: the given poses become the reference and, without drift, the odometry itself; each
// keyframe's cloud is its float32 triples; a malformed graph.txt names its line.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"
#include "runner/dataset_scan_sources.h"

namespace covox {
namespace tools {
namespace {

namespace fs = std::filesystem;

// A folder with two keyframes: the first 2 m along x turned 90 degrees about z, three points each.
fs::path write_graph_folder(const std::string& graph_text) {
  const fs::path folder =
      fs::temp_directory_path() / ("covoxslam_keyframe_graph_" + std::to_string(::getpid()));
  fs::remove_all(folder);
  for (const char* name : {"000000", "000001"}) {
    fs::create_directories(folder / name);
    const std::vector<float> points = {3.0f, 0.0f, 0.0f, 0.0f, 4.0f, 0.0f, 0.5f, 0.5f, 0.0f};
    std::ofstream file(folder / name / "points.bin", std::ios::binary);
    file.write(reinterpret_cast<const char*>(points.data()),
               static_cast<std::streamsize>(points.size() * sizeof(float)));
  }
  std::ofstream(folder / "graph.txt") << graph_text;
  return folder;
}

TEST(KeyframeGraphSource, GivenPosesAreTheOdometryWithoutDriftAndCloudsAreFloatTriples) {
  const double s = std::sqrt(0.5);
  const fs::path folder = write_graph_folder("v0 2 0 0 0 0 " + std::to_string(s) + " " +
                                             std::to_string(s) + "\nv1 5 1 0 0 0 0 1\n");
  LidarKeyframeScanOptions options;
  options.drift_scale = 0.0;
  options.keyframe_interval_s = 10.0;
  const std::unique_ptr<ScanSource> source =
      open_dataset_scan_source(folder.string(), RgbdScanOptions(), options);
  ASSERT_EQ(source->size(), 2u);
  ASSERT_EQ(source->reference().poses.size(), 2u);
  EXPECT_EQ(source->reference_kind(), ReferenceKind::kOtherEstimate);
  SourceScan scan;
  ASSERT_TRUE(source->next(&scan));
  EXPECT_EQ(scan.stamp_s, 0.0);
  EXPECT_NEAR((scan.T_odom_sensor.translation() - Eigen::Vector3d(2, 0, 0)).norm(), 0.0, 1e-12);
  // 90 degrees about z: the sensor's x axis points along the world's y.
  EXPECT_NEAR((scan.T_odom_sensor.linear().col(0) - Eigen::Vector3d(0, 1, 0)).norm(), 0.0, 1e-6);
  // The point 0.7 m away lies inside the default 2 m minimum range.
  ASSERT_EQ(scan.points_sensor_m.size(), 2u);
  EXPECT_EQ(scan.points_sensor_m[1].y, 4.0f);
  ASSERT_TRUE(source->next(&scan));
  EXPECT_EQ(scan.stamp_s, 10.0);
  EXPECT_FALSE(source->next(&scan));
  fs::remove_all(folder);
}

TEST(KeyframeGraphSource, AMalformedLineIsNamed) {
  const fs::path folder = write_graph_folder("v0 0 0 0 0 0 0 1\nv2 1 0 0 0 0 0 1\n");
  try {
    LidarKeyframeGraphScanSource source(folder.string(), LidarKeyframeScanOptions());
    ADD_FAILURE() << "no error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("expected 'v1"), std::string::npos) << error.what();
  }
  fs::remove_all(folder);
}

// The shared dump: five keyframes; with drift the odometry leaves the given poses.
TEST(KeyframeGraphSource, Kitti07DumpReadsFiveKeyframes) {
  const std::string folder = io::data_directory() + "/lidar-scans/kitti_07_dump";
  if (!fs::exists(folder)) GTEST_SKIP() << "shared data not found at '" << folder << "'";
  LidarKeyframeScanOptions options;
  LidarKeyframeGraphScanSource source(folder, options);
  ASSERT_EQ(source.size(), 5u);
  SourceScan scan;
  ASSERT_TRUE(source.next(&scan));
  EXPECT_GT(scan.points_sensor_m.size(), 10000u);
  size_t count = 1;
  while (source.next(&scan)) ++count;
  EXPECT_EQ(count, 5u);
  const Eigen::Vector3d given = source.reference().poses.back().position_m;
  EXPECT_GE((scan.T_odom_sensor.translation() - given).norm(), options.min_final_drift_m - 1e-9);
}

}  // namespace
}  // namespace tools
}  // namespace covox

// LiDAR keyframes in the MulRan layout with drift added to their recorded odometry (the HKU-2
// Livox folder of the shared data): as recorded, the odometry is odom_poses.txt itself; with
// added drift, it starts where the recording starts, ends at least the asked distance from where
// the recording ends, and is the same for the same seed.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/pose_file_readers.h"
#include "runner/dataset_scan_sources.h"

namespace covox {
namespace tools {
namespace {

namespace fs = std::filesystem;

std::string livox_folder() { return io::data_directory() + "/livox-hku-2"; }

// Every scan's odometry pose, in order.
std::vector<Eigen::Isometry3d> odometry_of(ScanSource* source) {
  std::vector<Eigen::Isometry3d> poses;
  SourceScan scan;
  while (source->next(&scan)) poses.push_back(scan.T_odom_sensor);
  return poses;
}

TEST(KeyframeFolderDrift, AsRecordedTheOdometryIsTheRecordedOne) {
  if (!fs::exists(livox_folder())) GTEST_SKIP() << "shared data not found at " << livox_folder();
  const std::vector<Eigen::Isometry3d> recorded =
      io::read_kitti_pose_file(livox_folder() + "/odom_poses.txt");
  LidarKeyframeScanSource source(livox_folder(), LidarKeyframeScanOptions());
  const std::vector<Eigen::Isometry3d> odometry = odometry_of(&source);
  ASSERT_EQ(odometry.size(), recorded.size());
  for (size_t i = 0; i < odometry.size(); ++i)
    ASSERT_TRUE(odometry[i].isApprox(recorded[i], 1e-12)) << "scan " << i;
  EXPECT_EQ(source.final_drift_m(), 0.0);
}

TEST(KeyframeFolderDrift, AddedDriftStartsAtTheRecordingAndEndsAtLeastThatFarOff) {
  if (!fs::exists(livox_folder())) GTEST_SKIP() << "shared data not found at " << livox_folder();
  const std::vector<Eigen::Isometry3d> recorded =
      io::read_kitti_pose_file(livox_folder() + "/odom_poses.txt");
  LidarKeyframeScanOptions options;
  options.added_drift_m = 0.5;
  options.drift_seed = 3;
  LidarKeyframeScanSource source(livox_folder(), options);
  const std::vector<Eigen::Isometry3d> odometry = odometry_of(&source);
  ASSERT_EQ(odometry.size(), recorded.size());
  EXPECT_TRUE(odometry.front().isApprox(recorded.front(), 1e-12));
  const double end_offset_m =
      (odometry.back().translation() - recorded.back().translation()).norm();
  EXPECT_GE(end_offset_m, 0.5);
  EXPECT_NEAR(source.final_drift_m(), end_offset_m, 1e-9);

  LidarKeyframeScanSource again(livox_folder(), options);
  const std::vector<Eigen::Isometry3d> repeated = odometry_of(&again);
  for (size_t i = 0; i < odometry.size(); ++i)
    ASSERT_TRUE(repeated[i].isApprox(odometry[i], 0.0)) << "scan " << i;
  options.drift_seed = 4;
  LidarKeyframeScanSource other_seed(livox_folder(), options);
  EXPECT_FALSE(odometry_of(&other_seed).back().isApprox(odometry.back(), 1e-6));
}

TEST(KeyframeFolderDrift, ANegativeDriftIsRefused) {
  if (!fs::exists(livox_folder())) GTEST_SKIP() << "shared data not found at " << livox_folder();
  LidarKeyframeScanOptions options;
  options.added_drift_m = -1.0;
  EXPECT_THROW(LidarKeyframeScanSource(livox_folder(), options), Error);
}

}  // namespace
}  // namespace tools
}  // namespace covox

// The non-ROS half of the nodelet's input handling: odometry poses interpolated at a cloud's
// stamp (or the reason they cannot be), the wait-or-drop decision for clouds whose pose is not
// known yet (missing tf / odometry), rate-limited drop counting, and reading every SLAM
// parameter by name with a bad one reported by that name.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/drop_counter.h"
#include "covoxslam/pipeline/slam_parameters.h"
#include "support/parameter_errors.h"
#include "covoxslam/pipeline/stamped_pose_buffer.h"

namespace covox {
namespace pipeline {
namespace {

Eigen::Isometry3d pose_at(double x, double y, double z, double yaw_rad) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(x, y, z);
  return pose;
}

TEST(StampedPoseBuffer, InterpolatesPositionLinearlyAndYawSpherically) {
  StampedPoseBuffer buffer;
  ASSERT_TRUE(buffer.add(10.0, pose_at(0, 0, 1, 0.0)));
  ASSERT_TRUE(buffer.add(10.5, pose_at(2, -1, 1, 0.8)));
  Eigen::Isometry3d pose;
  ASSERT_EQ(buffer.lookup(10.125, &pose), PoseLookup::kOk);
  EXPECT_NEAR(pose.translation().x(), 0.5, 1e-12);
  EXPECT_NEAR(pose.translation().y(), -0.25, 1e-12);
  EXPECT_NEAR(pose.translation().z(), 1.0, 1e-12);
  const Eigen::Vector3d x_axis = pose.linear().col(0);
  EXPECT_NEAR(std::atan2(x_axis.y(), x_axis.x()), 0.2, 1e-12);
  // Exactly on a sample.
  ASSERT_EQ(buffer.lookup(10.5, &pose), PoseLookup::kOk);
  EXPECT_NEAR(pose.translation().x(), 2.0, 1e-12);
}

TEST(StampedPoseBuffer, SaysWhyAStampCannotBeAnswered) {
  StampedPoseBufferConfig config;
  config.keep_s = 5.0;
  config.max_gap_s = 1.0;
  StampedPoseBuffer buffer(config);
  Eigen::Isometry3d pose;
  EXPECT_EQ(buffer.lookup(1.0, &pose), PoseLookup::kEmpty);
  for (int i = 0; i <= 100; ++i) ASSERT_TRUE(buffer.add(0.1 * i, pose_at(0.1 * i, 0, 0, 0)));
  EXPECT_EQ(buffer.lookup(10.01, &pose), PoseLookup::kAfterNewest);
  EXPECT_EQ(buffer.lookup(1.0, &pose), PoseLookup::kBeforeOldest);  // only the last 5 s are kept
  EXPECT_EQ(buffer.lookup(std::nan(""), &pose), PoseLookup::kBeforeOldest);
  ASSERT_TRUE(buffer.add(12.0, pose_at(1, 0, 0, 0)));
  EXPECT_EQ(buffer.lookup(11.0, &pose), PoseLookup::kGap);
  // Refused input: time going backwards, NaN, a non-rigid pose.
  EXPECT_FALSE(buffer.add(11.5, pose_at(0, 0, 0, 0)));
  EXPECT_FALSE(buffer.add(13.0, pose_at(std::nan(""), 0, 0, 0)));
  Eigen::Isometry3d scaled = pose_at(0, 0, 0, 0);
  scaled.linear() *= 2.0;
  EXPECT_FALSE(buffer.add(13.0, scaled));
  EXPECT_EQ(buffer.newest_stamp_s(), 12.0);
}

TEST(StampedPoseBuffer, PendingCloudsWaitUntilTheTimeoutThenDrop) {
  EXPECT_EQ(decide_pending(PoseLookup::kOk, 100.0, 0.5), PendingDecision::kUse);
  EXPECT_EQ(decide_pending(PoseLookup::kAfterNewest, 0.2, 0.5), PendingDecision::kWait);
  EXPECT_EQ(decide_pending(PoseLookup::kAfterNewest, 0.6, 0.5), PendingDecision::kDropTimedOut);
  EXPECT_EQ(decide_pending(PoseLookup::kEmpty, 0.6, 0.5), PendingDecision::kDropTimedOut);
  EXPECT_EQ(decide_pending(PoseLookup::kBeforeOldest, 0.0, 0.5), PendingDecision::kDropNever);
  EXPECT_EQ(decide_pending(PoseLookup::kGap, 0.0, 0.5), PendingDecision::kDropNever);
}

TEST(DropCounter, CountsEveryDropButLogsAtMostOncePerInterval) {
  DropCounter counter(5.0);
  int logged = 0;
  int64_t logged_total = 0;
  // 1000 drops over 20 s at 50 Hz.
  for (int i = 0; i < 1000; ++i) {
    if (counter.count(0.02 * i)) {
      ++logged;
      logged_total += counter.logged_batch();
    }
  }
  EXPECT_EQ(counter.total(), 1000);
  EXPECT_EQ(logged, 4);  // at 0, 5, 10, 15 s
  // Every logged line reports the drops since the previous one: together all but the tail.
  EXPECT_GT(logged_total, 750);
  EXPECT_LE(logged_total, 1000);
}

TEST(SlamParameters, ReadsEveryNamedParameter) {
  TextParameterSource source({{"device", "cpu"},
                              {"map.voxel_size_m", "0.1"},
                              {"map.voxels_per_side", "8"},
                              {"tsdf.truncation_distance_m", "0.3"},
                              {"tsdf.max_ray_length_m", "12.5"},
                              {"tsdf.use_const_weight", "true"},
                              {"tsdf.method", "simple"},
                              {"submaps.policy", "distance"},
                              {"submaps.distance_m", "7"},
                              {"queues.sensor_scans", "3"},
                              {"pose_graph.odometry_yaw_sigma_rad", "0.05"},
                              {"esdf.max_distance_m", "3"}});
  SlamConfig config;
  read_slam_config(source, &config);
  EXPECT_EQ(config.device, Device::kCpu);
  EXPECT_FLOAT_EQ(config.map.voxel_size_m, 0.1f);
  EXPECT_EQ(config.map.voxels_per_side, 8);
  EXPECT_FLOAT_EQ(config.tsdf.truncation_distance_m, 0.3f);
  EXPECT_FLOAT_EQ(config.tsdf.max_ray_length_m, 12.5f);
  EXPECT_TRUE(config.tsdf.use_const_weight);
  EXPECT_EQ(config.tsdf.method, integrators::TsdfIntegrationMethod::kSimple);
  EXPECT_EQ(config.submaps.policy, SubmapCreationPolicy::kDistanceTravelled);
  EXPECT_DOUBLE_EQ(config.submaps.distance_m, 7.0);
  EXPECT_EQ(config.sensor_queue_size, 3u);
  EXPECT_DOUBLE_EQ(config.odometry_yaw_sigma_rad, 0.05);
  EXPECT_FLOAT_EQ(config.esdf.esdf_max_distance_m, 3.0f);
  // Unset parameters keep their defaults.
  EXPECT_EQ(config.submap_queue_size, SlamConfig().submap_queue_size);
  for (const auto& name : {"map.voxel_size_m", "queues.sensor_scans", "submaps.policy", "device"}) {
    EXPECT_NE(std::find(slam_parameter_names().begin(), slam_parameter_names().end(), name),
              slam_parameter_names().end());
  }
}

using testing_support::expect_error_names;  // the error must name the wrong parameter

TEST(SlamParameters, BadValuesAreReportedByName) {
  expect_error_names({{"map.voxel_size_m", "-0.2"}}, "map.voxel_size_m");
  expect_error_names({{"map.voxel_size_m", "abc"}}, "map.voxel_size_m");
  expect_error_names({{"map.voxels_per_side", "12"}}, "map.voxels_per_side");
  expect_error_names({{"queues.sensor_scans", "0"}}, "queues.sensor_scans");
  expect_error_names({{"queues.sensor_scans", "-4"}}, "queues.sensor_scans");
  expect_error_names({{"submaps.policy", "sometimes"}}, "submaps.policy");
  expect_error_names({{"submaps.interval_s", "0"}}, "submaps.interval_s");
  expect_error_names({{"tsdf.method", "fast"}}, "tsdf.method");
  expect_error_names({{"tsdf.use_const_weight", "yes"}}, "tsdf.use_const_weight");
  expect_error_names({{"device", "tpu"}}, "device");
  expect_error_names({{"pose_graph.odometry_translation_sigma_vox", "nan"}},
                     "pose_graph.odometry_translation_sigma_vox");
  // Relations are checked by the integrator's validate(), which names the fields.
  expect_error_names({{"map.voxel_size_m", "0.5"}, {"tsdf.truncation_distance_m", "0.3"}},
                     "truncation_distance_m");
  expect_error_names({{"tsdf.min_ray_length_m", "6"}, {"tsdf.max_ray_length_m", "5"}},
                     "max_ray_length_m");
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

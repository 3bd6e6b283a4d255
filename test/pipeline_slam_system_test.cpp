// SlamSystem end to end on small simulated LiDAR scans of a hollow sphere: submaps appear when
// the policy says so, finish() flushes both queues, every scan is either integrated or counted as
// dropped, bad input never crashes, and shutting down without finish() does not hang.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <future>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/slam_system.h"
#include "support/analytic_scene.h"
#include "support/small_slam_config.h"

namespace covox {
namespace pipeline {
namespace {

// Small and fast on 2 cores: 8-voxel blocks, a short ESDF range, 64 x 8 rays per scan.
SlamConfig small_config() { return testing_support::small_slam_config(); }

// A scan at `stamp_s` from a sensor at (x, 0, 0) with heading `yaw`, inside a sphere of radius 4.
Scan sphere_scan(double stamp_s, double x_m, double yaw = 0.0) {
  testing_support::AnalyticScene scene;
  scene.shape = testing_support::Shape::kSphere;
  scene.radius = 4.0;
  Scan scan;
  scan.stamp_s = stamp_s;
  scan.T_odom_sensor.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  scan.T_odom_sensor.translation() = Eigen::Vector3d(x_m, 0.0, 0.0);
  scan.points_sensor_m =
      testing_support::simulate_lidar(scene, scan.T_odom_sensor, 64, 8, 40.0, 10.0);
  return scan;
}

std::vector<int64_t> scans_per_submap(const std::vector<SubmapInfo>& submaps) {
  std::vector<int64_t> scans;
  for (const SubmapInfo& submap : submaps) scans.push_back(submap.statistics.scans);
  return scans;
}

// The bookkeeping every run must satisfy: a scan is integrated or counted as dropped.
void expect_every_scan_accounted_for(const SlamCounters& counters) {
  EXPECT_EQ(counters.scans_integrated, counters.scans_received - counters.scans_dropped_total())
      << "received " << counters.scans_received << ", dropped " << counters.scans_dropped_total();
}

TEST(PipelineSlamSystem, TimePolicyStartsASubmapEveryInterval) {
  SlamConfig config = small_config();
  config.submaps.policy = SubmapCreationPolicy::kTimeInterval;
  config.submaps.interval_s = 1.0;
  SlamSystem slam(config);
  for (int k = 0; k < 10; ++k) ASSERT_TRUE(slam.add_scan(sphere_scan(0.25 * k, 0.05 * k)));
  slam.finish();
  const std::vector<SubmapInfo> submaps = slam.submaps();
  ASSERT_EQ(submaps.size(), 3u);
  EXPECT_EQ(scans_per_submap(submaps), (std::vector<int64_t>{4, 4, 2}));
  EXPECT_DOUBLE_EQ(submaps[0].statistics.start_stamp_s, 0.0);
  EXPECT_DOUBLE_EQ(submaps[1].statistics.start_stamp_s, 1.0);
  EXPECT_DOUBLE_EQ(submaps[2].statistics.start_stamp_s, 2.0);
  EXPECT_DOUBLE_EQ(submaps[0].statistics.end_stamp_s, 0.75);
}

TEST(PipelineSlamSystem, DistancePolicyStartsASubmapEveryDistance) {
  SlamConfig config = small_config();
  config.submaps.policy = SubmapCreationPolicy::kDistanceTravelled;
  config.submaps.distance_m = 1.0;
  SlamSystem slam(config);
  // 0.25 m per scan (exact in binary): new submaps at x = 1.0 and x = 2.0.
  for (int k = 0; k < 10; ++k) ASSERT_TRUE(slam.add_scan(sphere_scan(0.1 * (k + 1), 0.25 * k)));
  slam.finish();
  const std::vector<SubmapInfo> submaps = slam.submaps();
  EXPECT_EQ(scans_per_submap(submaps), (std::vector<int64_t>{4, 4, 2}));
  ASSERT_EQ(submaps.size(), 3u);
  EXPECT_NEAR(submaps[1].T_odom_submap.translation().x(), 1.0, 1e-12);
  EXPECT_NEAR(submaps[2].T_odom_submap.translation().x(), 2.0, 1e-12);
  EXPECT_NEAR(submaps[0].statistics.distance_travelled_m, 0.75, 1e-12);
}

TEST(PipelineSlamSystem, BlockPolicyStartsASubmapOnceTheBlockCountIsReached) {
  SlamConfig config = small_config();
  config.submaps.policy = SubmapCreationPolicy::kBlockCount;
  config.submaps.max_blocks = 1;  // every scan allocates blocks: one submap per scan
  {
    SlamSystem slam(config);
    for (int k = 0; k < 4; ++k) ASSERT_TRUE(slam.add_scan(sphere_scan(0.1 * k, 0.1 * k)));
    slam.finish();
    EXPECT_EQ(scans_per_submap(slam.submaps()), (std::vector<int64_t>{1, 1, 1, 1}));
  }
  config.submaps.max_blocks = 1000000;  // never reached: one submap
  {
    SlamSystem slam(config);
    for (int k = 0; k < 4; ++k) ASSERT_TRUE(slam.add_scan(sphere_scan(0.1 * k, 0.1 * k)));
    slam.finish();
    EXPECT_EQ(scans_per_submap(slam.submaps()), (std::vector<int64_t>{4}));
  }
}

TEST(PipelineSlamSystem, FinishFlushesBothQueuesAndEveryScanIsIntegratedOrCounted) {
  SlamConfig config = small_config();
  config.submaps.interval_s = 0.5;
  SlamSystem slam(config);
  int given = 0;
  for (int k = 0; k < 12; ++k) {
    slam.add_scan(sphere_scan(0.1 * (k + 1), 0.1 * k, 0.05 * k));
    ++given;
  }
  // Bad input of every kind, mixed in.
  Scan nan_pose = sphere_scan(10.0, 0.0);
  nan_pose.T_odom_sensor.translation().y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(slam.add_scan(nan_pose));
  Scan empty = sphere_scan(10.1, 0.0);
  empty.points_sensor_m.clear();
  EXPECT_FALSE(slam.add_scan(empty));
  EXPECT_FALSE(slam.add_scan(sphere_scan(0.05, 0.0)));  // stamp goes backwards
  Scan bad_colors = sphere_scan(10.2, 0.0);
  bad_colors.colors.resize(3);
  EXPECT_FALSE(slam.add_scan(bad_colors));
  given += 4;
  slam.finish();
  EXPECT_FALSE(slam.running());

  const SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.scans_received, given);
  EXPECT_EQ(counters.scans_dropped_invalid_pose, 1);
  EXPECT_EQ(counters.scans_dropped_empty_cloud, 1);
  EXPECT_EQ(counters.scans_dropped_bad_stamp, 1);
  EXPECT_EQ(counters.scans_dropped_bad_colors, 1);
  EXPECT_EQ(counters.scans_dropped_queue_full, 0);
  EXPECT_EQ(counters.scans_integrated, 12);
  expect_every_scan_accounted_for(counters);
  // Every submap created was finished and entered the graph (none dropped here).
  const std::vector<SubmapInfo> submaps = slam.submaps();
  EXPECT_EQ(counters.submaps_created, static_cast<int64_t>(submaps.size()));
  EXPECT_EQ(counters.submaps_finished, counters.submaps_created);
  EXPECT_EQ(counters.submaps_dropped_queue_full, 0);
  EXPECT_EQ(counters.odometry_constraints, counters.submaps_created - 1);
  EXPECT_GE(counters.optimizations, 1);
  int64_t scans_in_submaps = 0;
  for (const SubmapInfo& submap : submaps) {
    scans_in_submaps += submap.statistics.scans;
    EXPECT_GT(submap.mesh_triangles, 0) << "submap " << submap.id;
    EXPECT_FALSE(submap.bounding_box_world.isEmpty());
  }
  EXPECT_EQ(scans_in_submaps, 12);

  // With odometry constraints only, the corrected poses are the odometry poses.
  const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
  ASSERT_EQ(trajectory.size(), 12u);
  for (int k = 0; k < 12; ++k) {
    const Scan expected = sphere_scan(0.1 * (k + 1), 0.1 * k, 0.05 * k);
    EXPECT_DOUBLE_EQ(trajectory[k].stamp_s, expected.stamp_s);
    EXPECT_TRUE(trajectory[k].T_world_sensor.isApprox(expected.T_odom_sensor, 1e-6)) << k;
  }
  // Saving the map: one snapshot per finished submap, with its voxels.
  const std::vector<SubmapSnapshot> snapshots = slam.submap_snapshots();
  ASSERT_EQ(snapshots.size(), submaps.size());
  EXPECT_EQ(static_cast<int64_t>(snapshots[0].blocks.size()), submaps[0].statistics.blocks);
  for (const SubmapInfo& submap : submaps) {
    EXPECT_TRUE(submap.T_world_submap.isApprox(submap.T_odom_submap, 1e-6)) << submap.id;
  }
  const map::Mesh mesh = slam.combined_mesh();
  EXPECT_GT(mesh.triangle_count(), 0u);
  EXPECT_EQ(mesh.colors.size(), mesh.vertices_m.size());
  const SlamTimings timings = slam.timings();
  EXPECT_EQ(timings.tsdf.calls, 12);
  EXPECT_EQ(timings.esdf.calls, counters.submaps_finished);
  EXPECT_EQ(timings.mesh.calls, counters.submaps_finished);
  EXPECT_EQ(timings.sensor_queue_wait.calls, 12);
  EXPECT_EQ(timings.backend.calls, counters.optimizations);
  // finish() is idempotent and later scans are refused (counted).
  slam.finish();
  EXPECT_FALSE(slam.add_scan(sphere_scan(20.0, 0.0)));
  EXPECT_EQ(slam.counters().scans_rejected_not_running, 1);
  expect_every_scan_accounted_for(slam.counters());
}

TEST(PipelineSlamSystem, FullSensorQueueDropsTheOldestScansAndCountsThem) {
  SlamConfig config = small_config();
  config.sensor_queue_size = 3;
  config.start_threads = false;  // nothing consumes yet: the overflow is deterministic
  SlamSystem slam(config);
  for (int k = 0; k < 10; ++k) EXPECT_TRUE(slam.add_scan(sphere_scan(0.1 * (k + 1), 0.0)));
  EXPECT_EQ(slam.counters().scans_dropped_queue_full, 7);
  slam.finish();  // starts the threads, drains
  const SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.scans_integrated, 3);
  expect_every_scan_accounted_for(counters);
  // The newest three survived.
  const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
  ASSERT_EQ(trajectory.size(), 3u);
  EXPECT_DOUBLE_EQ(trajectory[0].stamp_s, 0.8);
  EXPECT_DOUBLE_EQ(trajectory[2].stamp_s, 1.0);
}

TEST(PipelineSlamSystem, NonFinitePosesAndStampsAreDroppedAndCounted) {
  SlamSystem slam(small_config());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Scan scan = sphere_scan(1.0, 0.0);
  scan.T_odom_sensor.linear()(0, 0) = nan;
  EXPECT_FALSE(slam.add_scan(scan));
  scan = sphere_scan(1.0, 0.0);
  scan.T_odom_sensor.translation().z() = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(slam.add_scan(scan));
  scan = sphere_scan(nan, 0.0);
  EXPECT_FALSE(slam.add_scan(scan));
  // A cloud with NaN points is not dropped: the integrator skips those points and counts them.
  scan = sphere_scan(2.0, 0.0);
  const size_t valid_points = scan.points_sensor_m.size();
  scan.points_sensor_m.push_back(Vec3f(static_cast<float>(nan), 0.0f, 0.0f));
  EXPECT_TRUE(slam.add_scan(scan));
  slam.finish();
  const SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.scans_dropped_invalid_pose, 2);
  EXPECT_EQ(counters.scans_dropped_bad_stamp, 1);
  EXPECT_EQ(counters.scans_integrated, 1);
  EXPECT_EQ(counters.points_integrated, static_cast<int64_t>(valid_points + 1));
  EXPECT_GE(counters.points_dropped_by_integrator, 1);
  expect_every_scan_accounted_for(counters);
}

TEST(PipelineSlamSystem, ShutdownWithoutFinishDoesNotHang) {
  auto run = std::async(std::launch::async, [] {
    SlamConfig config = small_config();
    config.submaps.interval_s = 0.2;
    auto slam = std::make_unique<SlamSystem>(config);
    for (int k = 0; k < 60; ++k) slam->add_scan(sphere_scan(0.1 * (k + 1), 0.01 * k));
    slam->shutdown();
    const SlamCounters counters = slam->counters();
    const bool refused = !slam->add_scan(sphere_scan(100.0, 0.0));
    slam.reset();  // the destructor after shutdown() must not hang either
    // And a system destroyed while busy, without shutdown() or finish().
    auto busy = std::make_unique<SlamSystem>(config);
    for (int k = 0; k < 30; ++k) busy->add_scan(sphere_scan(0.1 * (k + 1), 0.01 * k));
    busy.reset();
    return std::make_pair(counters, refused);
  });
  ASSERT_EQ(run.wait_for(std::chrono::seconds(30)), std::future_status::ready) << "shutdown hung";
  const auto [counters, refused] = run.get();
  EXPECT_TRUE(refused);
  EXPECT_EQ(counters.scans_received, 60);
  expect_every_scan_accounted_for(counters);
}

TEST(PipelineSlamSystem, FinishWithoutStartProcessesTheQueuedScans) {
  SlamConfig config = small_config();
  config.start_threads = false;
  SlamSystem slam(config);
  for (int k = 0; k < 3; ++k) slam.add_scan(sphere_scan(0.1 * (k + 1), 0.0));
  EXPECT_FALSE(slam.running());
  slam.finish();
  EXPECT_EQ(slam.counters().scans_integrated, 3);
  EXPECT_EQ(slam.submaps().size(), 1u);
}

TEST(PipelineSlamSystem, InvalidConfigurationNamesTheParameter) {
  SlamConfig config = small_config();
  config.sensor_queue_size = 0;
  try {
    SlamSystem slam(config);
    FAIL() << "expected covox::Error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("queues.sensor_scans"), std::string::npos)
        << error.what();
  }
  config = small_config();
  config.odometry_yaw_sigma_rad = -1.0;
  EXPECT_THROW(SlamSystem{config}, Error);
  config = small_config();
  config.submaps.policy = SubmapCreationPolicy::kDistanceTravelled;
  config.submaps.distance_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(SlamSystem{config}, Error);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

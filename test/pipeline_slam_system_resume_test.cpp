// SlamSystem::resume(): after finish() the system maps again. The finished submaps stay exactly
// as they were (frozen), the next scans go into new submaps linked to the last one by odometry,
// every scan is integrated or counted, and reset() / load_submaps() on a finished system are
// followed by mapping too. shutdown() is final: resume() refuses.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <thread>
#include <vector>

#include "covoxslam/pipeline/slam_system.h"
#include "support/analytic_scene.h"
#include "support/small_slam_config.h"

namespace covox {
namespace pipeline {
namespace {

// A scan at `stamp_s` from a sensor at (x, 0.1 x, 0) inside a hollow sphere of radius 4 m.
Scan scan_in_sphere(double stamp_s, double x_m) {
  testing_support::AnalyticScene sphere;
  sphere.shape = testing_support::Shape::kSphere;
  sphere.radius = 4.0;
  Scan scan;
  scan.stamp_s = stamp_s;
  scan.T_odom_sensor.translation() = Eigen::Vector3d(x_m, 0.1 * x_m, 0.0);
  scan.points_sensor_m =
      testing_support::simulate_lidar(sphere, scan.T_odom_sensor, 64, 8, 40.0, 10.0);
  return scan;
}

// Scans k = first .. first + count - 1 at 0.25 s, moving 5 cm each.
void add_scans(SlamSystem* slam, int first, int count) {
  for (int k = first; k < first + count; ++k)
    ASSERT_TRUE(slam->add_scan(scan_in_sphere(0.25 * (k + 1), 0.05 * k))) << "scan " << k;
}

TEST(PipelineSlamSystemResume, MappingContinuesInNewSubmapsAfterFinish) {
  SlamSystem slam(testing_support::small_slam_config());
  add_scans(&slam, 0, 8);
  slam.finish();
  EXPECT_FALSE(slam.running());
  const std::vector<SubmapInfo> frozen = slam.submaps();
  ASSERT_GE(frozen.size(), 2u);
  const map::Mesh frozen_mesh = slam.combined_mesh();
  const int64_t frozen_triangles = static_cast<int64_t>(frozen_mesh.triangle_count());

  ASSERT_TRUE(slam.resume());
  EXPECT_TRUE(slam.running());
  EXPECT_TRUE(slam.resume());  // running already: nothing changes
  // A scan stamped before the last accepted one is still refused after resume().
  EXPECT_FALSE(slam.add_scan(scan_in_sphere(0.1, 0.0)));
  add_scans(&slam, 8, 8);
  slam.finish();

  const SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.scans_integrated, 16);
  EXPECT_EQ(counters.scans_dropped_bad_stamp, 1);
  EXPECT_EQ(counters.scans_integrated, counters.scans_received - counters.scans_dropped_total());
  const std::vector<SubmapInfo> submaps = slam.submaps();
  ASSERT_GT(submaps.size(), frozen.size());
  // The submaps finished before resume() are unchanged: same ids, scans, blocks and triangles.
  int64_t frozen_mesh_triangles = 0;
  for (size_t k = 0; k < frozen.size(); ++k) {
    EXPECT_EQ(submaps[k].id, frozen[k].id);
    EXPECT_EQ(submaps[k].statistics.scans, frozen[k].statistics.scans);
    EXPECT_EQ(submaps[k].statistics.blocks, frozen[k].statistics.blocks);
    EXPECT_EQ(submaps[k].mesh_triangles, frozen[k].mesh_triangles);
    frozen_mesh_triangles += submaps[k].mesh_triangles;
  }
  EXPECT_EQ(frozen_mesh_triangles, frozen_triangles);
  // The new submaps hold the new scans and follow the old ones in the odometry chain.
  int64_t new_scans = 0;
  for (size_t k = frozen.size(); k < submaps.size(); ++k) {
    EXPECT_GT(submaps[k].id, frozen.back().id);
    EXPECT_GT(submaps[k].mesh_triangles, 0);
    EXPECT_GE(submaps[k].statistics.start_stamp_s, 0.25 * 9 - 1e-9);
    new_scans += submaps[k].statistics.scans;
  }
  EXPECT_EQ(new_scans, 8);
  EXPECT_EQ(counters.odometry_constraints, static_cast<int64_t>(submaps.size()) - 1);
  // The trajectory holds both stretches in order.
  const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
  ASSERT_EQ(trajectory.size(), 16u);
  for (int k = 0; k < 16; ++k) EXPECT_DOUBLE_EQ(trajectory[k].stamp_s, 0.25 * (k + 1));
}

TEST(PipelineSlamSystemResume, ResetOrLoadAfterFinishThenResumeMapsAgain) {
  SlamSystem slam(testing_support::small_slam_config());
  add_scans(&slam, 0, 6);
  slam.finish();
  std::vector<SubmapSnapshot> saved = slam.submap_snapshots();
  const size_t saved_count = saved.size();
  ASSERT_GE(saved_count, 1u);

  // reset() on a finished system, then resume(): an empty map whose stamps start again.
  slam.reset();
  EXPECT_TRUE(slam.submaps().empty());
  ASSERT_TRUE(slam.resume());
  add_scans(&slam, 0, 6);
  slam.finish();
  EXPECT_EQ(slam.corrected_trajectory().size(), 6u);
  EXPECT_GE(slam.submaps().size(), 1u);

  // load_submaps() on a finished system, then resume(): the loaded map plus new submaps.
  slam.load_submaps(std::move(saved));
  ASSERT_TRUE(slam.resume());
  add_scans(&slam, 0, 6);
  slam.finish();
  const std::vector<SubmapInfo> submaps = slam.submaps();
  ASSERT_GT(submaps.size(), saved_count);
  for (size_t k = 0; k < saved_count; ++k) EXPECT_TRUE(submaps[k].loaded) << k;
  for (size_t k = saved_count; k < submaps.size(); ++k) EXPECT_FALSE(submaps[k].loaded) << k;
  EXPECT_EQ(slam.corrected_trajectory().size(), 6u);
}

// Waits (at most 10 s) until both queues are empty: the threads have taken every scan and submap.
void wait_until_idle(const SlamSystem& slam) {
  for (int k = 0; k < 1000 && (slam.sensor_queue_length() > 0 || slam.submap_queue_length() > 0);
       ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

// The operator's order on a running node: finish, map on, snapshot, reset, map, load the
// snapshot while the threads run, map on: the loaded map plus the new submaps.
TEST(PipelineSlamSystemResume, LoadWhileRunningKeepsTheSubmapsMappedAfterIt) {
  SlamSystem slam(testing_support::small_slam_config());
  add_scans(&slam, 0, 6);
  slam.finish();
  ASSERT_TRUE(slam.resume());
  add_scans(&slam, 6, 6);
  slam.finish();
  ASSERT_TRUE(slam.resume());
  std::vector<SubmapSnapshot> saved = slam.submap_snapshots();
  const size_t saved_count = saved.size();
  ASSERT_GE(saved_count, 1u);
  slam.reset();
  ASSERT_TRUE(slam.resume());
  add_scans(&slam, 12, 6);
  wait_until_idle(slam);
  slam.load_submaps(std::move(saved));
  ASSERT_TRUE(slam.resume());
  add_scans(&slam, 18, 12);
  slam.finish();
  const std::vector<SubmapInfo> submaps = slam.submaps();
  ASSERT_GT(submaps.size(), saved_count);
  for (size_t k = 0; k < saved_count; ++k) EXPECT_TRUE(submaps[k].loaded) << k;
  for (size_t k = saved_count; k < submaps.size(); ++k) EXPECT_FALSE(submaps[k].loaded) << k;
  EXPECT_EQ(slam.corrected_trajectory().size(), 12u);
}

TEST(PipelineSlamSystemResume, ShutdownIsFinal) {
  SlamSystem slam(testing_support::small_slam_config());
  add_scans(&slam, 0, 2);
  slam.shutdown();
  EXPECT_FALSE(slam.resume());
  EXPECT_FALSE(slam.running());
  EXPECT_FALSE(slam.add_scan(scan_in_sphere(10.0, 0.0)));
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

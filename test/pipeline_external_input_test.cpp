// SlamSystem's external input: a loop closure with a known transform pulls two submaps together,
// GNSS positions pin the graph in the world, heights remove z drift, reset() empties the system,
// load_submaps() round-trips a map and the mapping that follows registers to it, and bad input is
// refused and counted.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <thread>
#include <vector>

#include "covoxslam/core/error.h"
#include "pipeline_test_scene.h"
#include "support/analytic_scene.h"
#include "support/small_slam_config.h"

namespace covox {
namespace pipeline {
namespace {

using namespace test_scene;

// Scans of a hollow sphere (cheap): for tests that need integrated scans but no registration.
SlamConfig sphere_config() {
  SlamConfig config = testing_support::small_slam_config();
  config.registration.enabled = false;
  return config;
}

Scan sphere_scan(double stamp_s, const Eigen::Isometry3d& T_odom_sensor) {
  testing_support::AnalyticScene scene;
  scene.shape = testing_support::Shape::kSphere;
  scene.radius = 6.0;
  Scan scan;
  scan.stamp_s = stamp_s;
  scan.T_odom_sensor = T_odom_sensor;
  scan.points_sensor_m =
      testing_support::simulate_lidar(scene, Eigen::Isometry3d::Identity(), 48, 6, 40.0, 10.0);
  return scan;
}

Eigen::Isometry3d tilted(const Eigen::Isometry3d& pose, double roll, double pitch) {
  Eigen::Isometry3d result = pose;
  result.linear() = pose.linear() * (Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                                     Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                                        .toRotationMatrix();
  return result;
}

double yaw_of(const Eigen::Matrix3d& rotation) {
  return std::atan2(rotation(1, 0), rotation(0, 0));
}

// Waits until the frontend has integrated `count` scans. External input refers to scans by stamp,
// so it must wait for them; the limit is generous because a loaded machine (the GPU suite under
// `ctest -j 4`) took over the 3 s this once allowed, and the stamps then read as unknown.
bool wait_for_integrated_scans(const SlamSystem& slam, int64_t count) {
  for (int spin = 0; spin < 6000 && slam.counters().scans_integrated < count; ++spin) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return slam.counters().scans_integrated >= count;
}

StampedPose pose_at(const std::vector<StampedPose>& trajectory, double stamp_s) {
  for (const StampedPose& pose : trajectory) {
    if (std::abs(pose.stamp_s - stamp_s) < 1e-9) return pose;
  }
  ADD_FAILURE() << "no pose at " << stamp_s;
  return StampedPose();
}

TEST(PipelineExternalInput, LoopClosureWithAKnownTransformPullsTwoSubmapsTogether) {
  SlamSystem slam(sphere_config());
  // Truth: a tilted sensor moving along x. Odometry: correct in the first second, then off by
  // 0.4 m and 4 degrees (a jump the loop closure must undo).
  std::vector<Eigen::Isometry3d> truth;
  const Eigen::Isometry3d jump = pose_4dof(0.3, -0.25, 0.1, 4.0 * kDegToRad);
  for (int k = 0; k < 8; ++k) {
    const double t = 0.25 * k;
    truth.push_back(
        tilted(pose_4dof(0.2 * k, 0.05 * k, 1.0, 0.1 * k), 3.0 * kDegToRad, -2.0 * kDegToRad));
    const Eigen::Isometry3d odometry = t < 1.0 ? truth.back() : jump * truth.back();
    ASSERT_TRUE(slam.add_scan(sphere_scan(t, odometry)));
  }
  ASSERT_TRUE(wait_for_integrated_scans(slam, 8));
  LoopClosure closure;
  closure.from_stamp_s = 0.5;
  closure.to_stamp_s = 1.5 + 0.01;  // between scans: the nearest within the tolerance is taken
  closure.T_from_to = truth[2].inverse() * truth[6];
  closure.information = Eigen::Matrix<double, 6, 6>::Identity() * 1e8;
  EXPECT_TRUE(slam.add_loop_closure(closure));
  slam.finish();

  const SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.loop_closures.received, 1);
  EXPECT_EQ(counters.loop_closures.added, 1);
  ASSERT_EQ(slam.submaps().size(), 2u);
  const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
  const Eigen::Isometry3d from = pose_at(trajectory, 0.5).T_world_sensor;
  const Eigen::Isometry3d to = pose_at(trajectory, 1.5).T_world_sensor;
  const Eigen::Isometry3d corrected_relative = from.inverse() * to;
  const Eigen::Isometry3d odometry_relative = (truth[2]).inverse() * (jump * truth[6]);
  std::printf("[ loop     ] relative pose error: odometry %.3f m, corrected %.5f m\n",
              (odometry_relative.translation() - closure.T_from_to.translation()).norm(),
              (corrected_relative.translation() - closure.T_from_to.translation()).norm());
  EXPECT_LT((corrected_relative.translation() - closure.T_from_to.translation()).norm(), 2e-3);
  EXPECT_NEAR(yaw_of((corrected_relative.linear() * closure.T_from_to.linear().transpose())), 0.0,
              1e-4);
  // The second submap moved; the first (the gauge) did not.
  const std::vector<SubmapInfo> submaps = slam.submaps();
  EXPECT_TRUE(submaps[0].T_world_submap.isApprox(submaps[0].T_odom_submap, 1e-9));
  EXPECT_GT(
      (submaps[1].T_world_submap.translation() - submaps[1].T_odom_submap.translation()).norm(),
      0.2);
  // T_world_odom is the correction of the latest submap: it undoes the jump.
  EXPECT_LT((slam.T_world_odom() * jump).translation().norm(), 2e-3);
}

TEST(PipelineExternalInput, LoopClosuresWaitForTheirSubmapsAndLostOnesAreCounted) {
  SlamConfig config = sphere_config();
  config.start_threads = false;  // nothing reaches the graph before finish()
  SlamSystem slam(config);
  for (int k = 0; k < 8; ++k)
    ASSERT_TRUE(slam.add_scan(sphere_scan(0.25 * k, pose_4dof(0.1 * k, 0, 0, 0))));
  // Not integrated yet: the stamps are unknown.
  LoopClosure closure;
  closure.from_stamp_s = 0.0;
  closure.to_stamp_s = 1.75;
  EXPECT_FALSE(slam.add_loop_closure(closure));
  EXPECT_EQ(slam.counters().loop_closures.rejected_unknown_stamp, 1);
  slam.finish();
  // After finish the scans are known; the closure waits until an optimisation is requested.
  closure.T_from_to = pose_4dof(0.7, 0.0, 0.0, 0.0);
  EXPECT_TRUE(slam.add_loop_closure(closure));
  EXPECT_EQ(slam.counters().loop_closures.added, 0);
  slam.request_optimization();
  EXPECT_EQ(slam.counters().loop_closures.added, 1);
  EXPECT_EQ(static_cast<int64_t>(slam.constraints().size()), 2);  // odometry + loop closure
}

TEST(PipelineExternalInput, AbsolutePositionsPinTheGraphInTheWorld) {
  SlamSystem slam(sphere_config());
  // The odometry frame is the world moved by 5 m and turned by 30 degrees; no drift.
  const Eigen::Isometry3d T_odom_world = pose_4dof(5.0, -3.0, 0.5, 30.0 * kDegToRad);
  std::vector<Eigen::Isometry3d> truth;
  for (int k = 0; k < 16; ++k) {
    truth.push_back(
        tilted(pose_4dof(0.3 * k, 0.1 * k * k * 0.05, 1.2, 0.05 * k), 2.0 * kDegToRad, 0.0));
    ASSERT_TRUE(slam.add_scan(sphere_scan(0.25 * k, T_odom_world * truth.back())));
  }
  ASSERT_TRUE(wait_for_integrated_scans(slam, 16));
  // GNSS fixes in three submaps, at sensors away from their submap origins (lever arms).
  const Eigen::Matrix3d information = Eigen::Matrix3d::Identity() * 1e4;
  for (int k : {2, 7, 11, 14}) {
    EXPECT_TRUE(slam.add_absolute_position(0.25 * k, truth[k].translation(), information)) << k;
  }
  slam.finish();
  const SlamCounters counters = slam.counters();
  std::printf("[ gnss     ] %lld optimisations, last: %s\n",
              static_cast<long long>(counters.optimizations),
              slam.last_solver_summary().report().c_str());
  EXPECT_EQ(counters.absolute_positions.added, 4);
  const Eigen::Isometry3d correction = slam.T_world_odom();
  const Eigen::Isometry3d expected = T_odom_world.inverse();
  std::printf("[ gnss     ] T_world_odom error: %.4f m, %.4f deg\n",
              (correction.translation() - expected.translation()).norm(),
              std::abs(yaw_of(correction.linear() * expected.linear().transpose())) / kDegToRad);
  EXPECT_LT((correction.translation() - expected.translation()).norm(), 0.01);
  EXPECT_LT(std::abs(yaw_of(correction.linear() * expected.linear().transpose())), 0.1 * kDegToRad);
  const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
  ASSERT_EQ(trajectory.size(), truth.size());
  for (size_t k = 0; k < truth.size(); ++k) {
    EXPECT_LT((trajectory[k].T_world_sensor.translation() - truth[k].translation()).norm(), 0.01)
        << k;
  }
}

// Feeds 16 scans, 0.25 s apart, at the true poses truth_at(k) seen through odometry that drifts
// 4 cm up per scan, and waits until they are integrated; fills `truth` and `odometry`.
template <class TruthAt>
void feed_z_drifting_scans(SlamSystem& slam, TruthAt truth_at,
                           std::vector<Eigen::Isometry3d>* truth,
                           std::vector<Eigen::Isometry3d>* odometry) {
  for (int k = 0; k < 16; ++k) {
    truth->push_back(truth_at(k));
    odometry->push_back(pose_4dof(0.0, 0.0, 0.04 * k, 0.0) * truth->back());
    ASSERT_TRUE(slam.add_scan(sphere_scan(0.25 * k, odometry->back())));
  }
  ASSERT_TRUE(wait_for_integrated_scans(slam, 16));
}

TEST(PipelineExternalInput, HeightsRemoveVerticalDrift) {
  SlamSystem slam(sphere_config());
  std::vector<Eigen::Isometry3d> truth, odometry;
  feed_z_drifting_scans(
      slam, [](int k) { return pose_4dof(0.3 * k, 0.0, 1.5 + 0.2 * std::sin(0.4 * k), 0.0); },
      &truth, &odometry);
  ASSERT_FALSE(HasFatalFailure());
  for (int k = 4; k < 16; k += 4)
    EXPECT_TRUE(slam.add_height(0.25 * k, truth[k].translation().z(), 1e4));
  slam.finish();
  EXPECT_EQ(slam.counters().heights.added, 3);
  const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
  double odometry_error = 0.0, corrected_error = 0.0;
  for (size_t k = 0; k < truth.size(); ++k) {
    odometry_error += std::abs(odometry[k].translation().z() - truth[k].translation().z());
    corrected_error +=
        std::abs(trajectory[k].T_world_sensor.translation().z() - truth[k].translation().z());
  }
  std::printf("[ height   ] mean |z error|: odometry %.3f m, corrected %.3f m\n",
              odometry_error / truth.size(), corrected_error / truth.size());
  // The drift inside a submap (up to 12 cm) stays; the submaps' offsets are gone.
  EXPECT_LT(corrected_error, 0.3 * odometry_error);
}

// Linear z drift and exact heights at the first scan of every submap but the first (whose
// correction is the identity: no drift yet). A step correction per submap leaves the drift inside
// each submap (4 to 12 cm); the interpolated correction (interpolate_trajectory_correction) is
// exact for linear drift up to the last submap, which has no successor and keeps its own.
TEST(PipelineExternalInput, InterpolatedCorrectionRemovesLinearDriftInsideSubmaps) {
  for (const bool interpolate : {false, true}) {
    SlamConfig config = sphere_config();
    config.interpolate_trajectory_correction = interpolate;
    SlamSystem slam(config);
    std::vector<Eigen::Isometry3d> truth, odometry;
    feed_z_drifting_scans(
        slam, [](int k) { return pose_4dof(0.3 * k, 0.1 * k, 1.5, 0.05 * k); }, &truth, &odometry);
    ASSERT_FALSE(HasFatalFailure());
    // Submaps start every second (4 scans); very sure heights at their first scans.
    for (int k = 4; k < 16; k += 4)
      EXPECT_TRUE(slam.add_height(0.25 * k, truth[k].translation().z(), 1e8));
    slam.finish();
    ASSERT_EQ(slam.submaps().size(), 4u);
    const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
    ASSERT_EQ(trajectory.size(), truth.size());
    double max_error_before_last = 0.0, max_error_last = 0.0;
    for (size_t k = 0; k < truth.size(); ++k) {
      const double error =
          (trajectory[k].T_world_sensor.translation() - truth[k].translation()).norm();
      // The heading is never changed by a pure z correction.
      EXPECT_NEAR(yaw_of(trajectory[k].T_world_sensor.linear()), 0.05 * k, 1e-9) << k;
      double& worst = k < 12 ? max_error_before_last : max_error_last;
      worst = std::max(worst, error);
    }
    std::printf(
        "[ interp   ] interpolate %d: max error %.4f m in submaps 0-2, %.4f m in the last\n",
        interpolate ? 1 : 0, max_error_before_last, max_error_last);
    if (interpolate) {
      EXPECT_LT(max_error_before_last, 2e-3);
    } else {
      EXPECT_GT(max_error_before_last,
                0.11);  // scan 3 of a submap: 3 x 4 cm of drift since its start
    }
    // The last submap keeps its own (step) correction either way.
    EXPECT_GT(max_error_last, 0.11);
    EXPECT_LT(max_error_last, 0.13);
  }
}

TEST(PipelineExternalInput, BadExternalInputIsRefusedAndCounted) {
  SlamSystem slam(sphere_config());
  for (int k = 0; k < 8; ++k)
    ASSERT_TRUE(slam.add_scan(sphere_scan(0.25 * k, pose_4dof(0.1 * k, 0, 0, 0))));
  ASSERT_TRUE(wait_for_integrated_scans(slam, 8));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  LoopClosure good;
  good.from_stamp_s = 0.0;
  good.to_stamp_s = 1.5;
  LoopClosure closure = good;
  closure.T_from_to.translation().x() = nan;
  EXPECT_FALSE(slam.add_loop_closure(closure));
  closure = good;
  closure.T_from_to.linear() *= 2.0;  // not a rotation
  EXPECT_FALSE(slam.add_loop_closure(closure));
  closure = good;
  closure.information(3, 3) = -1.0;  // not PSD
  EXPECT_FALSE(slam.add_loop_closure(closure));
  closure = good;
  closure.information(0, 5) = 0.5;  // not symmetric
  EXPECT_FALSE(slam.add_loop_closure(closure));
  closure = good;
  closure.information = Eigen::Matrix<double, 6, 6>::Zero();
  closure.information(3, 3) = closure.information(4, 4) =
      1.0;  // roll and pitch only: nothing in 4-DoF
  EXPECT_FALSE(slam.add_loop_closure(closure));
  closure = good;
  closure.to_stamp_s = 100.0;  // no scan there
  EXPECT_FALSE(slam.add_loop_closure(closure));
  closure = good;
  closure.from_stamp_s = -3.0;
  EXPECT_FALSE(slam.add_loop_closure(closure));
  closure = good;
  closure.to_stamp_s = 0.25;  // both in the first submap
  EXPECT_FALSE(slam.add_loop_closure(closure));
  EXPECT_TRUE(slam.add_loop_closure(good));

  EXPECT_FALSE(
      slam.add_absolute_position(0.5, Eigen::Vector3d(nan, 0, 0), Eigen::Matrix3d::Identity()));
  EXPECT_FALSE(
      slam.add_absolute_position(0.5, Eigen::Vector3d::Zero(), -Eigen::Matrix3d::Identity()));
  EXPECT_FALSE(
      slam.add_absolute_position(50.0, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity()));
  EXPECT_FALSE(slam.add_height(0.5, nan, 1.0));
  EXPECT_FALSE(slam.add_height(0.5, 1.0, 0.0));
  EXPECT_FALSE(slam.add_height(0.5, 1.0, -2.0));
  EXPECT_FALSE(slam.add_height(nan, 1.0, 1.0));
  EXPECT_FALSE(slam.add_height(60.0, 1.0, 1.0));
  slam.finish();

  const SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.loop_closures.received, 9);
  EXPECT_EQ(counters.loop_closures.rejected_bad_input, 5);
  EXPECT_EQ(counters.loop_closures.rejected_unknown_stamp, 2);
  EXPECT_EQ(counters.loop_closures.rejected_same_submap, 1);
  EXPECT_EQ(counters.loop_closures.added, 1);
  EXPECT_EQ(counters.absolute_positions.rejected_bad_input, 2);
  EXPECT_EQ(counters.absolute_positions.rejected_unknown_stamp, 1);
  EXPECT_EQ(counters.heights.rejected_bad_input, 4);
  EXPECT_EQ(counters.heights.rejected_unknown_stamp, 1);
  EXPECT_EQ(counters.heights.added, 0);
  EXPECT_EQ(counters.optimizations_failed, 0);
}

TEST(PipelineExternalInput, ResetEmptiesTheSystemAndMappingStartsAgain) {
  SlamSystem slam(sphere_config());
  for (int k = 0; k < 12; ++k)
    ASSERT_TRUE(slam.add_scan(sphere_scan(10.0 + 0.25 * k, pose_4dof(0.1 * k, 0, 0, 0))));
  // The backend finishes the first submaps in its own time; under a loaded machine (tests in
  // parallel, each with its own OpenMP threads) that can take seconds. The wait ends as soon as
  // they are there.
  for (int spin = 0; spin < 6000 && slam.submaps().size() < 2; ++spin) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_GE(slam.submaps().size(), 2u);
  const int64_t first_id_before = slam.submaps().front().id;
  LoopClosure closure;
  closure.from_stamp_s = 10.0;
  closure.to_stamp_s = 11.0;
  slam.add_loop_closure(closure);
  slam.reset();
  EXPECT_TRUE(slam.submaps().empty());
  EXPECT_TRUE(slam.corrected_trajectory().empty());
  EXPECT_TRUE(slam.constraints().empty());
  EXPECT_TRUE(slam.T_world_odom().isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_TRUE(slam.running());
  // A new map, with stamps before the old ones (a bag played again).
  for (int k = 0; k < 6; ++k)
    ASSERT_TRUE(slam.add_scan(sphere_scan(0.25 * k, pose_4dof(0.0, 0.1 * k, 0, 0))));
  slam.finish();
  const std::vector<SubmapInfo> submaps = slam.submaps();
  ASSERT_EQ(submaps.size(), 2u);
  EXPECT_GT(submaps.front().id, first_id_before);
  EXPECT_EQ(submaps[0].statistics.scans + submaps[1].statistics.scans, 6);
  const std::vector<StampedPose> trajectory = slam.corrected_trajectory();
  ASSERT_EQ(trajectory.size(), 6u);
  EXPECT_DOUBLE_EQ(trajectory.front().stamp_s, 0.0);
  const SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.resets, 1);
  EXPECT_EQ(counters.scans_integrated, counters.scans_received - counters.scans_dropped_total());
}

TEST(PipelineExternalInput, LoadSubmapsRoundTripsAndNewMappingRegistersToTheLoadedMap) {
  const sim::World world = make_yard();
  const sim::LidarConfig lidar = small_lidar();
  const SlamConfig config = yard_config();
  std::vector<SubmapSnapshot> saved;
  std::vector<SubmapInfo> saved_infos;
  {
    SlamSystem first(config);
    for (int k = 0; k <= 40; ++k) {
      const double t = 0.2 * k;
      first.add_scan(
          simulate(world, lidar, t, circle_pose(t), Eigen::Isometry3d::Identity(), k + 1).scan);
    }
    first.finish();
    saved = first.submap_snapshots();
    saved_infos = first.submaps();
  }
  ASSERT_GE(saved.size(), 2u);

  SlamSystem second(config);
  second.load_submaps(saved);
  const std::vector<SubmapInfo> loaded = second.submaps();
  ASSERT_EQ(loaded.size(), saved.size());
  for (size_t k = 0; k < loaded.size(); ++k) {
    EXPECT_TRUE(loaded[k].loaded);
    EXPECT_EQ(loaded[k].id, saved[k].id);
    EXPECT_TRUE(loaded[k].T_world_submap.isApprox(saved[k].T_world_submap, 1e-12));
    EXPECT_EQ(loaded[k].statistics.blocks, saved_infos[k].statistics.blocks);
    EXPECT_EQ(loaded[k].mesh_triangles, saved_infos[k].mesh_triangles);
  }
  // The voxels come back unchanged.
  const std::vector<SubmapSnapshot> again = second.submap_snapshots();
  ASSERT_EQ(again.size(), saved.size());
  for (size_t k = 0; k < saved.size(); ++k) {
    ASSERT_EQ(again[k].blocks.size(), saved[k].blocks.size());
    for (size_t b = 0; b < saved[k].blocks.size(); ++b) {
      ASSERT_EQ(again[k].blocks[b].index, saved[k].blocks[b].index);
      for (size_t v = 0; v < saved[k].blocks[b].tsdf.size(); ++v) {
        ASSERT_EQ(again[k].blocks[b].tsdf[v].distance_m, saved[k].blocks[b].tsdf[v].distance_m);
        ASSERT_EQ(again[k].blocks[b].tsdf[v].weight, saved[k].blocks[b].tsdf[v].weight);
      }
    }
  }

  // Mapping goes on over the same place, with odometry 0.4 m and 3 degrees off the loaded
  // map's frame: registration to the loaded submaps finds the offset.
  const Eigen::Isometry3d T_odom_world = pose_4dof(0.3, -0.25, 0.05, 3.0 * kDegToRad);
  for (int k = 0; k <= 25; ++k) {
    const double t = 100.0 + 0.2 * k;
    second.add_scan(
        simulate(world, lidar, t, circle_pose(0.2 * k + 1.0), T_odom_world, 1000 + k).scan);
  }
  second.finish();
  const SlamCounters counters = second.counters();
  EXPECT_EQ(counters.submaps_loaded, static_cast<int64_t>(saved.size()));
  EXPECT_GE(counters.registration.accepted, 1);
  const std::vector<SubmapInfo> after = second.submaps();
  for (size_t k = 0; k < saved.size(); ++k) {
    EXPECT_TRUE(after[k].T_world_submap.isApprox(saved[k].T_world_submap, 1e-12))
        << "loaded submaps stay fixed";
  }
  ASSERT_GT(after.size(), saved.size());
  EXPECT_GT(after[saved.size()].id, saved.back().id);
  const Eigen::Isometry3d correction = second.T_world_odom();
  const Eigen::Isometry3d expected = T_odom_world.inverse();
  std::printf("[ load     ] relocalised against the loaded map: %.3f m, %.3f deg off\n",
              (correction.translation() - expected.translation()).norm(),
              std::abs(yaw_of(correction.linear() * expected.linear().transpose())) / kDegToRad);
  EXPECT_LT((correction.translation() - expected.translation()).norm(), 0.05);
  EXPECT_LT(std::abs(yaw_of(correction.linear() * expected.linear().transpose())), 0.3 * kDegToRad);
}

// A map loaded from its compact forms (what the node's load_map does) under a device budget
// that holds about one submap: the submaps past the budget enter the store compact and never
// decoded, the loaded map saves to the same bytes, and meshes and slices are the ones of the same
// map loaded without a budget.
TEST(PipelineExternalInput, LoadingCompactFormsStaysWithinTheDeviceBudget) {
  const sim::World world = make_yard();
  const sim::LidarConfig lidar = small_lidar();
  std::vector<SubmapSnapshot> saved;
  std::vector<std::vector<uint8_t>> saved_bytes;
  {
    SlamSystem first(yard_config());
    for (int k = 0; k * 0.4 <= 18.0; ++k) {
      const double t = 0.4 * k;
      first.add_scan(
          simulate(world, lidar, t, circle_pose(t), Eigen::Isometry3d::Identity(), k + 1).scan);
    }
    first.finish();
    first.write_submaps([&](int64_t id, const Eigen::Isometry3d& T_world_submap,
                            const std::vector<uint8_t>& encoded) {
      saved.push_back(SubmapSnapshot{id, T_world_submap, {}, encoded});
      saved_bytes.push_back(encoded);
    });
  }
  ASSERT_GE(saved.size(), 4u);

  SlamConfig unbounded_config = yard_config();
  unbounded_config.memory.device_budget_mb = 0.0;
  SlamSystem unbounded(unbounded_config);
  unbounded.load_submaps(saved);
  SlamConfig bounded_config = yard_config();
  bounded_config.memory.device_budget_mb = 1.0;  // one or two of the yard's submaps
  SlamSystem bounded(bounded_config);
  bounded.load_submaps(saved);

  const SubmapStoreCounters memory = bounded.counters().memory;
  EXPECT_GE(memory.submaps_compact, 2);
  EXPECT_EQ(memory.submaps_resident + memory.submaps_compact, static_cast<int64_t>(saved.size()));
  EXPECT_LE(memory.resident_bytes, int64_t{1} << 20);
  EXPECT_EQ(memory.restores, 0) << "nothing was decoded twice";
  // Staged within the budget as they were built: none was resident past it and compacted after.
  EXPECT_EQ(memory.compactions, 0);
  std::vector<std::vector<uint8_t>> again;
  bounded.write_submaps([&](int64_t, const Eigen::Isometry3d&,
                            const std::vector<uint8_t>& encoded) { again.push_back(encoded); });
  EXPECT_TRUE(again == saved_bytes) << "save -> load -> save changed the bytes";
  const std::vector<SubmapInfo> infos = bounded.submaps();
  const std::vector<SubmapInfo> reference = unbounded.submaps();
  ASSERT_EQ(infos.size(), reference.size());
  for (size_t k = 0; k < infos.size(); ++k) {
    EXPECT_EQ(infos[k].mesh_triangles, reference[k].mesh_triangles);
    map::Mesh mesh;
    Eigen::Isometry3d T_world_submap;
    ASSERT_TRUE(bounded.submap_mesh(infos[k].id, &mesh, &T_world_submap));
    EXPECT_EQ(static_cast<int64_t>(mesh.triangle_count()), reference[k].mesh_triangles);
  }
  EXPECT_EQ(bounded.esdf_slice_world(1.0).size(), unbounded.esdf_slice_world(1.0).size());

  std::vector<SubmapSnapshot> truncated = saved;
  truncated.back().encoded.resize(truncated.back().encoded.size() / 2);
  EXPECT_THROW(bounded.load_submaps(truncated), Error);
  EXPECT_EQ(bounded.submaps().size(), saved.size());
}

TEST(PipelineExternalInput, LoadSubmapsRefusesBadSnapshotsAndKeepsTheMap) {
  SlamSystem slam(sphere_config());
  for (int k = 0; k < 6; ++k)
    ASSERT_TRUE(slam.add_scan(sphere_scan(0.25 * k, pose_4dof(0.1 * k, 0, 0, 0))));
  slam.finish();
  std::vector<SubmapSnapshot> snapshots = slam.submap_snapshots();
  ASSERT_EQ(snapshots.size(), 2u);
  std::vector<SubmapSnapshot> tilted_pose = snapshots;
  tilted_pose[1].T_world_submap = tilted(tilted_pose[1].T_world_submap, 0.1, 0.0);
  EXPECT_THROW(slam.load_submaps(tilted_pose), Error);
  std::vector<SubmapSnapshot> repeated = snapshots;
  repeated[1].id = repeated[0].id;
  EXPECT_THROW(slam.load_submaps(repeated), Error);
  std::vector<SubmapSnapshot> broken = snapshots;
  broken[0].blocks[0].tsdf.resize(3);
  EXPECT_THROW(slam.load_submaps(broken), Error);
  EXPECT_EQ(slam.submaps().size(), 2u);
  EXPECT_FALSE(slam.submaps()[0].loaded);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

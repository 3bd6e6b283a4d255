// Registration constraints in the running SLAM system: a LiDAR circles a yard for a lap and a
// bit while its odometry drifts; the corrected trajectory must be clearly closer to the truth
// than the odometry. Also: each rejection reason of the registration step is counted.
#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "pipeline_test_scene.h"

namespace covox {
namespace pipeline {
namespace {

using namespace test_scene;

struct DriftRun {
  double odometry_rmse_m = 0.0;
  double corrected_rmse_m = 0.0;
  double odometry_final_error_m = 0.0;
  double corrected_final_error_m = 0.0;
  SlamCounters counters;
  std::vector<SubmapInfo> submaps;
};

DriftRun run_drifting_lap(const SlamConfig& config, double duration_s, const Drift& drift) {
  const sim::World world = make_yard();
  const sim::LidarConfig lidar = small_lidar();
  SlamSystem slam(config);
  std::vector<Eigen::Isometry3d> truth, odometry;
  const double period_s = 0.2;  // 5 Hz keeps the test short; the vehicle moves 0.2 m per scan
  for (int k = 0; k * period_s <= duration_s; ++k) {
    const double t = k * period_s;
    SimulatedScan s =
        simulate(world, lidar, t, circle_pose(t), drift.at(t), static_cast<uint64_t>(k + 1));
    truth.push_back(s.T_world_sensor);
    odometry.push_back(s.scan.T_odom_sensor);
    EXPECT_TRUE(slam.add_scan(std::move(s.scan)));
  }
  slam.finish();
  DriftRun run;
  std::vector<Eigen::Isometry3d> corrected;
  for (const StampedPose& pose : slam.corrected_trajectory())
    corrected.push_back(pose.T_world_sensor);
  EXPECT_EQ(corrected.size(), truth.size());
  if (corrected.size() != truth.size()) return run;
  run.odometry_rmse_m = position_rmse_m(odometry, truth);
  run.corrected_rmse_m = position_rmse_m(corrected, truth);
  run.odometry_final_error_m = (odometry.back().translation() - truth.back().translation()).norm();
  run.corrected_final_error_m =
      (corrected.back().translation() - truth.back().translation()).norm();
  run.counters = slam.counters();
  run.submaps = slam.submaps();
  return run;
}

Drift lap_drift() {
  Drift drift;
  drift.yaw_rate_rad_per_s = 0.25 * kDegToRad;
  drift.bias_m_per_s = Eigen::Vector3d(0.03, -0.02, 0.008);
  return drift;
}

TEST(PipelineDriftCorrection, RegistrationPullsTheDriftingTrajectoryBackToTheTruth) {
  const SlamConfig config = yard_config();
  // 1.15 laps of a 6 m circle at 1 m/s: the last submaps see the start again.
  const DriftRun run = run_drifting_lap(config, 43.0, lap_drift());
  std::printf(
      "[ drift    ] position RMSE: odometry %.3f m, corrected %.3f m; final error: odometry %.3f "
      "m, "
      "corrected %.3f m\n",
      run.odometry_rmse_m, run.corrected_rmse_m, run.odometry_final_error_m,
      run.corrected_final_error_m);
  const RegistrationCounts& r = run.counters.registration;
  std::printf(
      "[ drift    ] %zu submaps; registrations attempted %lld, accepted %lld, rejected: failed "
      "%lld, "
      "too far %lld, too few points %lld; optimisations %lld\n",
      run.submaps.size(), static_cast<long long>(r.attempted), static_cast<long long>(r.accepted),
      static_cast<long long>(r.rejected_failed), static_cast<long long>(r.rejected_too_far),
      static_cast<long long>(r.rejected_too_few_points),
      static_cast<long long>(run.counters.optimizations));
  ASSERT_GE(run.submaps.size(), 9u);
  EXPECT_GT(run.odometry_rmse_m, 1.0);  // the drift is real
  // Every new submap registers at least to its predecessor.
  EXPECT_GE(r.accepted, static_cast<int64_t>(run.submaps.size()) - 1);
  EXPECT_EQ(r.attempted,
            r.accepted + r.rejected_failed + r.rejected_too_far + r.rejected_too_few_points);
  EXPECT_LT(run.corrected_rmse_m, 0.35 * run.odometry_rmse_m);
  EXPECT_LT(run.corrected_rmse_m, 0.3);
  EXPECT_LT(run.corrected_final_error_m, 0.3 * run.odometry_final_error_m);
  EXPECT_EQ(run.counters.optimizations_failed, 0);
}

// voxgraph's joint optimisation: the point residuals of every overlapping pair inside the solve.
TEST(PipelineDriftCorrection, JointRegistrationAlsoPullsTheTrajectoryBackToTheTruth) {
  SlamConfig config = yard_config();
  config.registration.mode = RegistrationMode::kJoint;
  const DriftRun run = run_drifting_lap(config, 43.0, lap_drift());
  std::printf(
      "[ joint    ] position RMSE: odometry %.3f m, corrected %.3f m; %lld pairs as dense terms\n",
      run.odometry_rmse_m, run.corrected_rmse_m,
      static_cast<long long>(run.counters.registration.joint_pairs));
  EXPECT_GE(run.counters.registration.joint_pairs, static_cast<int64_t>(run.submaps.size()) - 1);
  EXPECT_EQ(run.counters.registration.accepted, 0);  // no pairwise constraints in this mode
  EXPECT_LT(run.corrected_rmse_m, 0.35 * run.odometry_rmse_m);
  EXPECT_LT(run.corrected_rmse_m, 0.3);
  EXPECT_EQ(run.counters.optimizations_failed, 0);
}

TEST(PipelineDriftCorrection, WithoutRegistrationTheCorrectedTrajectoryIsTheOdometry) {
  SlamConfig config = yard_config();
  config.registration.enabled = false;
  const DriftRun run = run_drifting_lap(config, 12.0, lap_drift());
  EXPECT_EQ(run.counters.registration.attempted, 0);
  EXPECT_NEAR(run.corrected_rmse_m, run.odometry_rmse_m, 1e-6);
}

TEST(PipelineDriftCorrection, EachRejectionReasonIsCounted) {
  // Too far: no alignment may move the guess by more than 0.1 mm.
  SlamConfig config = yard_config();
  config.registration.acceptance.max_correction_m = 1e-4;
  config.registration.acceptance.max_correction_rad = 1e-6;
  DriftRun run = run_drifting_lap(config, 12.0, lap_drift());
  std::printf("[ rejects  ] attempted %lld, too far %lld, failed %lld, too few %lld\n",
              static_cast<long long>(run.counters.registration.attempted),
              static_cast<long long>(run.counters.registration.rejected_too_far),
              static_cast<long long>(run.counters.registration.rejected_failed),
              static_cast<long long>(run.counters.registration.rejected_too_few_points));
  const RegistrationCounts& counts = run.counters.registration;
  EXPECT_GE(counts.attempted, 4);
  EXPECT_EQ(counts.accepted, 0);
  // The short last submap (one scan) may also fall short of points; every other pair is too far.
  EXPECT_GE(counts.rejected_too_far, counts.attempted - 2);
  EXPECT_EQ(counts.rejected_too_far + counts.rejected_too_few_points + counts.rejected_failed,
            counts.attempted);
  // Too few points: more than a submap has.
  config = yard_config();
  config.registration.acceptance.min_points = 1000000;
  run = run_drifting_lap(config, 12.0, lap_drift());
  EXPECT_GE(run.counters.registration.attempted, 2);
  EXPECT_EQ(run.counters.registration.rejected_too_few_points, run.counters.registration.attempted);
  EXPECT_EQ(run.counters.registration.accepted, 0);
}

TEST(PipelineDriftCorrection, RegistrationParametersAreValidatedByName) {
  auto expect_named = [](SlamConfig config, const char* name) {
    try {
      SlamSystem slam(config);
      ADD_FAILURE() << "expected covox::Error naming " << name;
    } catch (const Error& error) {
      EXPECT_NE(std::string(error.what()).find(name), std::string::npos) << error.what();
    }
  };
  SlamConfig config = yard_config();
  config.registration.sampling.ratio = 0.0f;
  expect_named(config, "registration.sampling.ratio");
  config = yard_config();
  config.registration.information.point_sigma_m = -1.0;
  expect_named(config, "registration.information.point_sigma_m");
  config = yard_config();
  config.registration.acceptance.max_correction_rad = 4.0;
  expect_named(config, "registration.acceptance.max_correction_rad");
  config = yard_config();
  config.registration.acceptance.max_correction_m = std::numeric_limits<double>::quiet_NaN();
  expect_named(config, "registration.acceptance.max_correction_m");
  config = yard_config();
  config.registration.alignment.robust_loss_scale_m = 0.0;
  expect_named(config, "registration.alignment.robust_loss_scale_m");
  config = yard_config();
  config.external_stamp_tolerance_s = -0.1;
  expect_named(config, "external_stamp_tolerance_s");
  EXPECT_EQ(parse_robust_loss("huber"), backend::RobustLoss::kHuber);
  EXPECT_EQ(parse_robust_loss("cauchy"), backend::RobustLoss::kCauchy);
  EXPECT_THROW(parse_robust_loss("tukey"), Error);
  EXPECT_EQ(parse_registration_distance("esdf"), backend::RegistrationDistance::kEsdf);
  EXPECT_EQ(parse_registration_mode("joint"), RegistrationMode::kJoint);
  EXPECT_EQ(parse_registration_mode("pairwise"), RegistrationMode::kPairwise);
  EXPECT_THROW(parse_registration_mode("both"), Error);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

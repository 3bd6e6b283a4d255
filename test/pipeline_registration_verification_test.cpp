// Registrations are verified before they enter the pose graph: the odometry test's covariance,
// and on real data (7-Scenes redkitchen, frames 0-599, where the camera returns to places it saw)
// no accepted registration is wrong against the dataset's true poses, and the corrected
// trajectory is better than the drifted odometry it started from.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "constraint_evaluation.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/pipeline/registration_constraints.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "dataset_scan_sources.h"
#include "slam_run.h"

namespace covox {
namespace pipeline {
namespace {

constexpr double kPi = 3.14159265358979323846;

RegistrationOdometry odometry_at(double x, double y, double yaw, double path_m) {
  RegistrationOdometry odometry;
  odometry.known = true;
  odometry.pose.x = x;
  odometry.pose.y = y;
  odometry.pose.yaw = yaw;
  odometry.path_m = path_m;
  odometry.drift_m_per_m = 0.1;
  odometry.drift_rad_per_m = 0.02;
  return odometry;
}

TEST(RegistrationVerification, MahalanobisUsesTheDriftAlongThePathAndThePointsCovariance) {
  // Submap j at the origin, submap i 1 m ahead along a path of 2 m; the measurement is 0.3 m
  // further in x and 0.05 rad more in yaw than the odometry says.
  const RegistrationOdometry j = odometry_at(0.0, 0.0, 0.0, 1.0);
  const RegistrationOdometry i = odometry_at(1.0, 0.0, 0.0, 3.0);
  backend::Pose4Dof measured;
  measured.x = 1.3;
  measured.yaw = 0.05;
  const double floor_m = 0.04, floor_rad = kPi / 180.0;
  // Odometry only (points information zero): sigma = drift * path + floor per component.
  const double sigma_m = 0.1 * 2.0 + floor_m, sigma_rad = 0.02 * 2.0 + floor_rad;
  const double expected = std::pow(0.3 / sigma_m, 2) + std::pow(0.05 / sigma_rad, 2);
  EXPECT_NEAR(odometry_mahalanobis_sq(measured, j, i, Eigen::Matrix4d::Zero(), floor_m, floor_rad),
              expected, 1e-9 * expected);
  // The points' covariance adds to each component's variance.
  const Eigen::Vector4d points_variance(0.01, 0.02, 0.03, 0.001);
  const Eigen::Matrix4d points_information = points_variance.cwiseInverse().asDiagonal();
  const double with_points =
      0.09 / (sigma_m * sigma_m + 0.01) + 0.0025 / (sigma_rad * sigma_rad + 0.001);
  EXPECT_NEAR(odometry_mahalanobis_sq(measured, j, i, points_information, floor_m, floor_rad),
              with_points, 1e-9 * with_points);
  // The error is taken in j's heading frame: turning both submaps leaves the distance alone.
  const RegistrationOdometry j_turned = odometry_at(0.0, 0.0, 1.0, 1.0);
  const RegistrationOdometry i_turned = odometry_at(std::cos(1.0), std::sin(1.0), 1.0, 3.0);
  EXPECT_NEAR(odometry_mahalanobis_sq(measured, j_turned, i_turned, Eigen::Matrix4d::Zero(),
                                      floor_m, floor_rad),
              expected, 1e-9 * expected);
}

// Real data: every accepted registration of the rgbd preset on redkitchen frames 0-599 (drift
// seed 1, the runner's default drift) lies within 0.1 m and 5 degrees of the true relative pose
// of its two submaps, and the corrected trajectory beats the odometry.
TEST(RegistrationVerification, RedkitchenRevisitsAcceptOnlyRightRegistrations) {
  const std::string folder = io::data_directory() + "/7scenes-redkitchen-long";
  if (!std::filesystem::exists(folder))
    GTEST_SKIP() << "shared data not found at '" << folder << "'";
  tools::RgbdScanOptions options;
  tools::RgbdScanSource source(folder, options);
  ASSERT_GE(source.size(), 600u);
  SlamConfig config = load_preset("rgbd");
  tools::SlamRunOptions run_options;
  run_options.progress_bar = false;
  const tools::SlamRunResult result = tools::run_slam_system(source, config, run_options);

  const double tolerance_m = 0.1, tolerance_rad = 5.0 * kPi / 180.0;
  const tools::ConstraintEvaluation evaluation = tools::evaluate_registration_constraints(
      source.reference(), result.submaps, result.constraints, tolerance_m, tolerance_rad);
  EXPECT_EQ(evaluation.unevaluated, 0);
  EXPECT_GE(evaluation.constraints.size(), 10u);  // the revisits are not all thrown away
  for (const tools::ConstraintError& e : evaluation.constraints) {
    EXPECT_LE(e.error_m, tolerance_m) << "submap " << e.from_submap << " -> " << e.to_submap;
    EXPECT_LE(e.error_yaw_rad, tolerance_rad)
        << "submap " << e.from_submap << " -> " << e.to_submap;
  }
  const tools::SlamRunEvaluation ate =
      tools::evaluate_slam_run(source, result, tools::AlignmentMode::kTranslationYaw, 0.1);
  ASSERT_TRUE(ate.available) << ate.problem;
  EXPECT_LT(ate.corrected.absolute_position_m.rmse, ate.odometry.absolute_position_m.rmse);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

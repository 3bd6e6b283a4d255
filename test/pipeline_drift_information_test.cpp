// The accuracy floor of registration constraints (registration_constraints.h): the information a
// constraint carries is the points' information with a floor added to its covariance, checked
// against a direct evaluation of (information^-1 + floor)^-1 and against the closed form of a
// ground-only overlap (z known, x, y and yaw free).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <limits>
#include <string>

#include "covoxslam/pipeline/registration_constraints.h"

namespace covox {
namespace pipeline {
namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

// J^T J / sigma^2 of a few hundred random point Jacobians: full rank, millimetre-level sigmas,
// like an alignment on walls and ground.
Eigen::Matrix4d wall_and_ground_information() {
  Eigen::Matrix4d information = Eigen::Matrix4d::Zero();
  std::srand(7);
  for (int k = 0; k < 400; ++k) {
    const Eigen::Vector4d jacobian =
        Eigen::Vector4d::Random().cwiseProduct(Eigen::Vector4d(1.0, 1.0, 1.0, 10.0));
    information += jacobian * jacobian.transpose() / (0.1 * 0.1);
  }
  return information;
}

TEST(PipelineDriftInformation, FullRankInformationGetsTheFloorAddedToItsCovariance) {
  const Eigen::Matrix4d information = wall_and_ground_information();
  const double sigma_m = 0.2, sigma_yaw_rad = 1.0 * kDegToRad;
  const Eigen::Matrix4d floored = floored_information(information, sigma_m, sigma_yaw_rad);
  Eigen::Matrix4d covariance = information.inverse();
  covariance.diagonal() += Eigen::Vector4d(sigma_m * sigma_m, sigma_m * sigma_m, sigma_m * sigma_m,
                                           sigma_yaw_rad * sigma_yaw_rad);
  const Eigen::Matrix4d expected = covariance.inverse();
  EXPECT_LT((floored - expected).norm(), 1e-9 * expected.norm()) << floored << "\n\n" << expected;
  // The points alone claim millimetres; with the floor no direction is surer than the floor.
  const Eigen::Matrix4d floored_covariance = floored.inverse();
  for (int k = 0; k < 3; ++k) {
    EXPECT_LT(std::sqrt(information.inverse()(k, k)), 0.05 * sigma_m);
    EXPECT_GE(std::sqrt(floored_covariance(k, k)), sigma_m);
  }
  EXPECT_GE(std::sqrt(floored_covariance(3, 3)), sigma_yaw_rad);
}

TEST(PipelineDriftInformation, GroundOnlyOverlapKeepsItsFreeDirectionsFree) {
  // Only z is measured (flat ground seen by both submaps): x, y and yaw carry no information, and
  // the floor must not invent any; z's variance is the points' plus the floor's.
  Eigen::Matrix4d information = Eigen::Matrix4d::Zero();
  information(2, 2) = 1e6;
  const double sigma_m = 0.2;
  const Eigen::Matrix4d floored = floored_information(information, sigma_m, 1.0 * kDegToRad);
  EXPECT_NEAR(floored(2, 2), 1.0 / (1e-6 + sigma_m * sigma_m), 1e-9);
  for (int k : {0, 1, 3}) {
    for (int l = 0; l < 4; ++l) EXPECT_NEAR(floored(k, l), 0.0, 1e-12) << k << ", " << l;
  }
}

TEST(PipelineDriftInformation, ZeroFloorsLeaveThePointsInformationUnchanged) {
  const Eigen::Matrix4d information = wall_and_ground_information();
  EXPECT_EQ(floored_information(information, 0.0, 0.0), information);
  // Only a yaw floor: translations keep (nearly) all of the points' sureness.
  const Eigen::Matrix4d yaw_only = floored_information(information, 0.0, 1.0 * kDegToRad);
  EXPECT_GE(std::sqrt(yaw_only.inverse()(3, 3)), 1.0 * kDegToRad);
  EXPECT_LT(std::sqrt(yaw_only.inverse()(0, 0)), 0.2);
}

TEST(PipelineDriftInformation, FloorsAreValidatedByName) {
  SubmapRegistrationConfig config;
  validate(config);
  config.information.min_sigma_vox = -0.1;
  try {
    validate(config);
    FAIL() << "a negative min_sigma_vox was accepted";
  } catch (const std::exception& error) {
    EXPECT_NE(std::string(error.what()).find("registration.information.min_sigma_vox"),
              std::string::npos)
        << error.what();
  }
  config.information.min_sigma_vox = 1.0;
  config.information.min_sigma_yaw_rad = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(validate(config), std::exception);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

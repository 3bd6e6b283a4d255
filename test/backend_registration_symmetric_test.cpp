// Symmetric registration (registration.h): the 4-DoF inverse and its Jacobian, the two-way normal
// equations against differences of their own cost, and the two-way aligner on a known offset.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <memory>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/registration.h"
#include "covoxslam/core/error.h"
#include "support/per_device_cache.h"
#include "support/registration_room.h"
#include "support/test_devices.h"

namespace covox {
namespace backend {
namespace {

using testing_support::DeviceTest;
using testing_support::isometry_of;
using testing_support::kDegToRad;

// Two scans of the registration room, 0.1 m voxels, each submap with its own registration points.
// A type of its own: once_per_device caches one value per type.
struct TwoWayPair : testing_support::ScannedSubmapPair {};

const TwoWayPair& two_way_pair(Device device) {
  return testing_support::once_per_device<TwoWayPair>(device, [](Device d) {
    return TwoWayPair{
        testing_support::scan_submap_pair(d, testing_support::registration_room(),
                                          Pose4Dof{-0.38, 0.31, -0.06, -6.0 * kDegToRad}, 0.1f)};
  });
}

TEST(RegistrationInversePose, MatchesTheRigidInverseAndItsDifferences) {
  const Pose4Dof T{1.3, -0.7, 0.4, 37.0 * kDegToRad};
  const Pose4Dof inverse = inverse_pose_4dof(T);
  // Reference: Eigen's inverse of the rigid transform.
  const Eigen::Isometry3d reference = isometry_of(T).inverse();
  EXPECT_NEAR(inverse.x, reference.translation().x(), 1e-12);
  EXPECT_NEAR(inverse.y, reference.translation().y(), 1e-12);
  EXPECT_NEAR(inverse.z, reference.translation().z(), 1e-12);
  EXPECT_NEAR(inverse.yaw, std::atan2(reference.linear()(1, 0), reference.linear()(0, 0)), 1e-12);
  const Eigen::Matrix4d analytic = inverse_pose_4dof_jacobian(T);
  for (int axis = 0; axis < 4; ++axis) {
    const double step = 1e-6;
    Pose4Dof plus = T, minus = T;
    double* plus_fields[4] = {&plus.x, &plus.y, &plus.z, &plus.yaw};
    double* minus_fields[4] = {&minus.x, &minus.y, &minus.z, &minus.yaw};
    *plus_fields[axis] += step;
    *minus_fields[axis] -= step;
    const Pose4Dof a = inverse_pose_4dof(plus), b = inverse_pose_4dof(minus);
    const Eigen::Vector4d numeric =
        Eigen::Vector4d(a.x - b.x, a.y - b.y, a.z - b.z, a.yaw - b.yaw) / (2.0 * step);
    EXPECT_LT((numeric - analytic.col(axis)).norm(), 1e-8) << "column " << axis;
  }
}

class SymmetricRegistrationTest : public DeviceTest {};

// The reverse terms go through the chain rule of the inverse and a weight scale: their gradient
// must still be the derivative of the summed cost. Checked against central differences of the
// cost (a robust loss and a scale other than 1 included), away from the minimum.
TEST_P(SymmetricRegistrationTest, GradientIsTheDerivativeOfTheCost) {
  const TwoWayPair& pair = two_way_pair(device());
  const Stream stream(device());
  const SymmetricRegistrationPair view = pair.symmetric(2.5);
  RegistrationResidualConfig config;
  config.loss = RobustLoss::kCauchy;
  config.loss_scale = 0.5;
  const Pose4Dof at{pair.true_T_Sj_Si.x + 0.05, pair.true_T_Sj_Si.y - 0.04,
                    pair.true_T_Sj_Si.z + 0.03, pair.true_T_Sj_Si.yaw + 1.5 * kDegToRad};
  const RegistrationNormalEquations base =
      symmetric_registration_normal_equations(view, at, config, stream);
  const RegistrationNormalEquations forward =
      registration_normal_equations(*pair.points_i, *pair.map_j, at, Pose4Dof(), config, stream);
  ASSERT_GT(forward.used_points, 1000);
  ASSERT_GT(base.used_points - forward.used_points, 1000) << "the reverse direction adds no points";
  for (int axis = 0; axis < 4; ++axis) {
    const double step = 1e-6;
    Pose4Dof plus = at, minus = at;
    double* plus_fields[4] = {&plus.x, &plus.y, &plus.z, &plus.yaw};
    double* minus_fields[4] = {&minus.x, &minus.y, &minus.z, &minus.yaw};
    *plus_fields[axis] += step;
    *minus_fields[axis] -= step;
    const RegistrationNormalEquations p =
        symmetric_registration_normal_equations(view, plus, config, stream);
    const RegistrationNormalEquations m =
        symmetric_registration_normal_equations(view, minus, config, stream);
    ASSERT_EQ(p.used_points, base.used_points);
    ASSERT_EQ(m.used_points, base.used_points);
    const double numeric = (p.cost - m.cost) / (2.0 * step);
    EXPECT_NEAR(base.gradient_i(axis), numeric, 1e-4 * std::abs(numeric) + 1e-3) << "axis " << axis;
  }
}

TEST_P(SymmetricRegistrationTest, AlignerRecoversKnownOffset) {
  const TwoWayPair& pair = two_way_pair(device());
  const Stream stream(device());
  RegistrationAlignerConfig config;
  config.residual.loss = RobustLoss::kHuber;
  config.residual.loss_scale = 0.1;
  const Pose4Dof truth = pair.true_T_Sj_Si;
  const Pose4Dof offsets[] = {{0.3, -0.3, 0.2, 10.0 * kDegToRad},
                              {-0.35, 0.2, -0.15, -8.0 * kDegToRad}};
  for (const Pose4Dof& offset : offsets) {
    const Pose4Dof initial{truth.x + offset.x, truth.y + offset.y, truth.z + offset.z,
                           truth.yaw + offset.yaw};
    const RegistrationResult result =
        align_submaps_symmetric(pair.symmetric(1.0), initial, config, stream);
    const double translation_error_m = std::sqrt(std::pow(result.T_Sj_Si.x - truth.x, 2) +
                                                 std::pow(result.T_Sj_Si.y - truth.y, 2) +
                                                 std::pow(result.T_Sj_Si.z - truth.z, 2));
    const double yaw_error_deg = std::abs(result.T_Sj_Si.yaw - truth.yaw) / kDegToRad;
    std::printf(
        "[ registration ] %s symmetric, offset (%.2f, %.2f, %.2f m, %.1f deg): error %.4f m, %.4f "
        "deg, "
        "%d iterations, %lld points used\n",
        to_string(device()), offset.x, offset.y, offset.z, offset.yaw / kDegToRad,
        translation_error_m, yaw_error_deg, result.iterations,
        static_cast<long long>(result.used_points));
    EXPECT_TRUE(result.converged);
    EXPECT_LT(translation_error_m, 0.02);
    EXPECT_LT(yaw_error_deg, 0.2);
    EXPECT_LT(result.final_cost, result.initial_cost);
  }
}

TEST_P(SymmetricRegistrationTest, IncompletePairOrBadScaleIsAnError) {
  const TwoWayPair& pair = two_way_pair(device());
  const Stream stream(device());
  const RegistrationAlignerConfig config;
  SymmetricRegistrationPair missing = pair.symmetric(1.0);
  missing.points_j = nullptr;
  EXPECT_THROW(align_submaps_symmetric(missing, pair.true_T_Sj_Si, config, stream), Error);
  for (const double scale : {0.0, -1.0, std::nan("")}) {
    EXPECT_THROW(align_submaps_symmetric(pair.symmetric(scale), pair.true_T_Sj_Si, config, stream),
                 Error);
  }
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(SymmetricRegistrationTest);

}  // namespace
}  // namespace backend
}  // namespace covox

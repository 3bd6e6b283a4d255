// Batched pair registration (registration_batch.h): its sums against the one-pair reference
// (registration_normal_equations, symmetric_registration_normal_equations), and pairs aligned in
// lock step ending exactly where each ends alone.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "covoxslam/backend/registration.h"
#include "covoxslam/backend/registration_batch.h"
#include "covoxslam/core/error.h"
#include "support/per_device_cache.h"
#include "support/registration_room.h"
#include "support/test_devices.h"

namespace covox {
namespace backend {
namespace {

using testing_support::DeviceTest;
using testing_support::kDegToRad;

// Two scans of the registration room, 0.1 m voxels (a type of its own for once_per_device).
struct BatchRoomPair : testing_support::ScannedSubmapPair {};

const BatchRoomPair& room_pair(Device device) {
  return testing_support::once_per_device<BatchRoomPair>(device, [](Device d) {
    return BatchRoomPair{
        testing_support::scan_submap_pair(d, testing_support::registration_room(),
                                          Pose4Dof{0.42, -0.27, 0.05, 7.0 * kDegToRad}, 0.1f)};
  });
}

RegistrationBatchPair one_way(const BatchRoomPair& pair, const Pose4Dof& start) {
  RegistrationBatchPair batch;
  batch.points_i = pair.points_i.get();
  batch.map_j = pair.map_j.get();
  batch.start_T_Sj_Si = start;
  return batch;
}

RegistrationBatchPair two_way(const BatchRoomPair& pair, const Pose4Dof& start, double scale) {
  RegistrationBatchPair batch = one_way(pair, start);
  batch.points_j = pair.points_j.get();
  batch.map_i = pair.map_i.get();
  batch.reverse_weight_scale = scale;
  return batch;
}

Pose4Dof offset_from(const Pose4Dof& truth, double dx, double dy, double dz, double dyaw_deg) {
  return Pose4Dof{truth.x + dx, truth.y + dy, truth.z + dz, truth.yaw + dyaw_deg * kDegToRad};
}

void expect_same_sums(const RegistrationNormalEquations& batch,
                      const RegistrationNormalEquations& reference, const char* what) {
  EXPECT_EQ(batch.used_points, reference.used_points) << what;
  EXPECT_EQ(batch.skipped_points, reference.skipped_points) << what;
  EXPECT_NEAR(batch.cost, reference.cost, 1e-9 * std::abs(reference.cost)) << what;
  const double h_scale = reference.hessian_i.cwiseAbs().maxCoeff();
  const double g_scale = reference.gradient_i.cwiseAbs().maxCoeff();
  EXPECT_LT((batch.hessian_i - reference.hessian_i).cwiseAbs().maxCoeff(), 1e-9 * h_scale) << what;
  EXPECT_LT((batch.gradient_i - reference.gradient_i).cwiseAbs().maxCoeff(), 1e-9 * g_scale)
      << what;
}

class RegistrationBatchTest : public DeviceTest {};

// The batch evaluates the reverse direction as submap j's points in the field of a moving
// submap i (the field pose's Jacobian), the reference through the inverse pose and its chain
// rule, with the weight scale on the loss: the same sums by two routes. A coarse level too.
TEST_P(RegistrationBatchTest, SumsAreThoseOfEachPairAlone) {
  const BatchRoomPair& pair = room_pair(device());
  const Stream stream(device());
  const Pose4Dof at = offset_from(pair.true_T_Sj_Si, 0.06, -0.05, 0.02, 1.5);
  const Pose4Dof elsewhere = offset_from(pair.true_T_Sj_Si, -0.2, 0.1, -0.05, -4.0);
  for (const int stride : {1, 4}) {
    RegistrationResidualConfig config;
    config.loss = RobustLoss::kCauchy;
    config.loss_scale = 0.5;
    config.coarse_stride_vox = stride;
    const std::vector<RegistrationBatchPair> pairs = {two_way(pair, at, 2.5), one_way(pair, at),
                                                      two_way(pair, elsewhere, 1.0)};
    const std::vector<RegistrationNormalEquations> sums =
        registration_batch_normal_equations(pairs, {at, at, elsewhere}, config, stream);
    ASSERT_EQ(sums.size(), 3u);
    ASSERT_GT(sums[1].used_points, 500);
    ASSERT_GT(sums[0].used_points - sums[1].used_points, 500) << "no reverse points";
    SymmetricRegistrationPair reference = pair.symmetric(2.5);
    expect_same_sums(sums[0],
                     symmetric_registration_normal_equations(reference, at, config, stream),
                     "symmetric, scale 2.5");
    expect_same_sums(
        sums[1],
        registration_normal_equations(*pair.points_i, *pair.map_j, at, Pose4Dof(), config, stream),
        "one-way");
    reference.reverse_weight_scale = 1.0;
    expect_same_sums(sums[2],
                     symmetric_registration_normal_equations(reference, elsewhere, config, stream),
                     "symmetric elsewhere");
  }
}

// Lock step changes no pair's path: a pair's sums do not depend on the other pairs, so each
// outcome is bit for bit the outcome of that pair aligned alone, whatever the others do (converge
// early or late, fail at the start).
TEST_P(RegistrationBatchTest, PairsInLockStepEndWhereEachEndsAlone) {
  const BatchRoomPair& pair = room_pair(device());
  const Stream stream(device());
  RegistrationAlignerConfig config;
  config.coarse_levels = 2;
  config.residual.loss = RobustLoss::kHuber;
  config.residual.loss_scale = 0.1;
  const Pose4Dof truth = pair.true_T_Sj_Si;
  const std::vector<RegistrationBatchPair> pairs = {
      two_way(pair, offset_from(truth, 0.3, -0.25, 0.15, 8.0), 1.0),
      one_way(pair, offset_from(truth, -0.2, 0.3, -0.1, -5.0)),
      two_way(pair, offset_from(truth, 12.0, 9.0, 0.0, 0.0), 1.0),  // no overlap
      two_way(pair, offset_from(truth, 0.05, 0.05, 0.0, 1.0), 2.0)};
  const int64_t min_points = 50;
  const std::vector<RegistrationBatchOutcome> together =
      align_submap_pairs(pairs, config, stream, min_points);
  ASSERT_EQ(together.size(), pairs.size());
  EXPECT_EQ(together[2].status, RegistrationBatchOutcome::Status::kTooFewAtStart);
  EXPECT_LT(together[2].points_at_start, min_points);
  for (size_t k = 0; k < pairs.size(); ++k) {
    const RegistrationBatchOutcome alone =
        align_submap_pairs({pairs[k]}, config, stream, min_points).front();
    EXPECT_EQ(together[k].status, alone.status) << "pair " << k;
    EXPECT_EQ(together[k].points_at_start, alone.points_at_start) << "pair " << k;
    EXPECT_EQ(together[k].result.iterations, alone.result.iterations) << "pair " << k;
    EXPECT_EQ(together[k].result.converged, alone.result.converged) << "pair " << k;
    EXPECT_EQ(together[k].result.used_points, alone.result.used_points) << "pair " << k;
    EXPECT_EQ(together[k].result.T_Sj_Si.x, alone.result.T_Sj_Si.x) << "pair " << k;
    EXPECT_EQ(together[k].result.T_Sj_Si.y, alone.result.T_Sj_Si.y) << "pair " << k;
    EXPECT_EQ(together[k].result.T_Sj_Si.z, alone.result.T_Sj_Si.z) << "pair " << k;
    EXPECT_EQ(together[k].result.T_Sj_Si.yaw, alone.result.T_Sj_Si.yaw) << "pair " << k;
    EXPECT_EQ(together[k].result.final_cost, alone.result.final_cost) << "pair " << k;
    if (k == 2) continue;
    const RegistrationResult& result = together[k].result;
    EXPECT_EQ(together[k].status, RegistrationBatchOutcome::Status::kAligned) << "pair " << k;
    EXPECT_TRUE(result.converged) << "pair " << k;
    EXPECT_LT(std::hypot(result.T_Sj_Si.x - truth.x, result.T_Sj_Si.y - truth.y,
                         result.T_Sj_Si.z - truth.z),
              0.02)
        << "pair " << k;
    EXPECT_LT(std::abs(result.T_Sj_Si.yaw - truth.yaw), 0.2 * kDegToRad) << "pair " << k;
  }
  // Without the count at the start the pair without overlap fails in the aligner instead.
  const RegistrationBatchOutcome unchecked = align_submap_pairs({pairs[2]}, config, stream).front();
  EXPECT_EQ(unchecked.status, RegistrationBatchOutcome::Status::kFailed);
  EXPECT_NE(unchecked.failure.find("do not overlap"), std::string::npos) << unchecked.failure;
}

TEST_P(RegistrationBatchTest, IncompletePairsAndSettingsAreErrors) {
  const BatchRoomPair& pair = room_pair(device());
  const Stream stream(device());
  const RegistrationAlignerConfig config;
  RegistrationBatchPair half = two_way(pair, pair.true_T_Sj_Si, 1.0);
  half.map_i = nullptr;
  EXPECT_THROW(align_submap_pairs({half}, config, stream), Error);
  RegistrationBatchPair no_map = one_way(pair, pair.true_T_Sj_Si);
  no_map.map_j = nullptr;
  EXPECT_THROW(align_submap_pairs({no_map}, config, stream), Error);
  EXPECT_THROW(align_submap_pairs({two_way(pair, pair.true_T_Sj_Si, 0.0)}, config, stream), Error);
  RegistrationBatchPair not_finite = one_way(pair, pair.true_T_Sj_Si);
  not_finite.start_T_Sj_Si.yaw = std::nan("");
  EXPECT_THROW(align_submap_pairs({not_finite}, config, stream), Error);
  RegistrationAlignerConfig no_iterations;
  no_iterations.max_iterations = 0;
  EXPECT_THROW(align_submap_pairs({one_way(pair, pair.true_T_Sj_Si)}, no_iterations, stream),
               Error);
  EXPECT_THROW(
      registration_batch_normal_equations({one_way(pair, pair.true_T_Sj_Si)}, {}, {}, stream),
      Error);
  EXPECT_TRUE(align_submap_pairs({}, config, stream).empty());
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(RegistrationBatchTest);

}  // namespace
}  // namespace backend
}  // namespace covox

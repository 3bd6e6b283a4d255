#pragma once
// Many submap pairs aligned in lock step (registration.h's aligner, batched).
//
// A new submap is registered against up to max_partners earlier ones. Aligned one after another,
// every Levenberg-Marquardt iterate of every pair waits for its own reductions, and on a GPU
// those waits, not the arithmetic, are the cost. Here each round evaluates the requested pose of
// every unfinished pair (both directions of a symmetric pair) in one pass over all their points
// and brings every pair's sums back with one wait; each pair's own Levenberg-Marquardt then picks
// its next pose on the host. A pair's sums do not depend on the other pairs in the batch
// (registration_batch_ops.h), so a pair aligned in a batch ends exactly where it ends alone.
#include <string>
#include <vector>

#include "covoxslam/backend/registration.h"

namespace covox {
namespace backend {

// One pair: submap i's points in submap j's field, and with points_j and map_i also submap j's
// points in submap i's field (symmetric registration, see SymmetricRegistrationPair). All on one
// device.
struct RegistrationBatchPair {
  const RegistrationPoints* points_i = nullptr;
  const map::TsdfMap* map_j = nullptr;
  const RegistrationPoints* points_j = nullptr;  // null: one-way
  const map::TsdfMap* map_i = nullptr;           // null: one-way
  double reverse_weight_scale = 1.0;
  Pose4Dof start_T_Sj_Si;  // where the alignment starts
};

struct RegistrationBatchOutcome {
  enum class Status {
    kAligned,        // `result` holds the alignment (converged or not)
    kTooFewAtStart,  // fewer than min_points_at_start points of i inside j's field at the start
    kFailed,         // the fine level had too few points or a singular system: see `failure`
  };
  Status status = Status::kFailed;
  std::string failure;
  int64_t points_at_start = 0;  // with min_points_at_start > 0: the count that was tested
  RegistrationResult result;
};

// The IRLS sums of each pair at its pose in `poses_T_Sj_Si` (both directions when symmetric, as
// symmetric_registration_normal_equations), all in one pass. Throws covox::Error on an invalid
// pair or configuration.
std::vector<RegistrationNormalEquations> registration_batch_normal_equations(
    const std::vector<RegistrationBatchPair>& pairs, const std::vector<Pose4Dof>& poses_T_Sj_Si,
    const RegistrationResidualConfig& config, const Stream& stream);

// Aligns every pair from its start with align_submaps' coarse-to-fine Levenberg-Marquardt.
// min_points_at_start > 0: first counts each pair's points of i inside j's field at its start with
// the fine residual (one direction), and a pair with fewer is not aligned (kTooFewAtStart).
// Throws covox::Error on an invalid pair or configuration (a pair that cannot be aligned is an
// outcome, not an error).
std::vector<RegistrationBatchOutcome> align_submap_pairs(
    const std::vector<RegistrationBatchPair>& pairs, const RegistrationAlignerConfig& config,
    const Stream& stream, int64_t min_points_at_start = 0);

}  // namespace backend
}  // namespace covox

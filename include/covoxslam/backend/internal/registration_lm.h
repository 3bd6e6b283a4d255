#pragma once
// The Levenberg-Marquardt of one pair's alignment (registration.h, RegistrationAlignerConfig) as
// a state machine that names the pose (and level) whose sums it needs next, so that a driver can
// evaluate the requests of many pairs together (registration_batch.h). Coarse-to-fine: the LM on
// the ESDF every 2^L voxels, L = coarse_levels ... 1, each level from where the previous ended (a
// failed level leaves the start unchanged), then on the fine residual, whose failure is the
// pair's. Each level: Marquardt damping, a step kept when the mean cost per used point does not
// rise (points leaving the other field drop out of the sum), converged when a step is below the
// tolerances (a coarse level's scaled with its stride, and at most coarse_max_iterations steps).
#include <string>

#include "covoxslam/backend/registration_batch.h"

namespace covox {
namespace backend {

// What a pair needs evaluated: its sums at `pose` at `level` (0: the fine residual, L >= 1: the
// ESDF every 2^L voxels), both directions unless `forward_only`.
struct RegistrationLmRequest {
  Pose4Dof pose;
  int level = 0;
  bool forward_only = false;
};

class RegistrationLm {
 public:
  // Throws covox::Error on max_iterations or coarse_max_iterations < 1, coarse_levels outside
  // [0, 10] or coarse_tolerance_scale < 1.
  RegistrationLm(const Pose4Dof& start_T_Sj_Si, const RegistrationAlignerConfig& config,
                 int64_t min_points_at_start);

  bool done() const { return done_; }
  const RegistrationLmRequest& request() const { return request_; }
  // The sums at request(); moves to the next request or finishes.
  void take(const RegistrationNormalEquations& sums);
  const RegistrationBatchOutcome& outcome() const { return outcome_; }

 private:
  enum class Phase { kCountAtStart, kFirst, kTrial };
  void begin_level(int level);
  void plan_step();
  void judge_trial(const RegistrationNormalEquations& trial);
  void end_level(bool converged);
  void fail_level(const std::string& why);
  void finish(RegistrationBatchOutcome::Status status);

  RegistrationAlignerConfig config_;
  int64_t min_points_at_start_ = 0;
  Pose4Dof start_, pose_;
  RegistrationNormalEquations current_;
  Eigen::Vector4d step_ = Eigen::Vector4d::Zero();
  double lambda_ = 0.0;
  double level_initial_cost_ = 0.0;
  int level_ = 0, iterations_ = 0, coarse_iterations_ = 0;
  Phase phase_ = Phase::kFirst;
  RegistrationLmRequest request_;
  bool done_ = false;
  RegistrationBatchOutcome outcome_;
};

}  // namespace backend
}  // namespace covox

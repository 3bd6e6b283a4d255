#include "covoxslam/backend/internal/registration_lm.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "covoxslam/core/error.h"

namespace covox {
namespace backend {

RegistrationLm::RegistrationLm(const Pose4Dof& start_T_Sj_Si,
                               const RegistrationAlignerConfig& config, int64_t min_points_at_start)
    : config_(config), min_points_at_start_(min_points_at_start), start_(start_T_Sj_Si) {
  if (config.max_iterations < 1) {
    throw Error("align_submaps: max_iterations must be >= 1, got " +
                std::to_string(config.max_iterations));
  }
  if (config.coarse_levels < 0 || config.coarse_levels > 10) {
    throw Error("align_submaps: coarse_levels must be in [0, 10], got " +
                std::to_string(config.coarse_levels));
  }
  if (config.coarse_max_iterations < 1) {
    throw Error("align_submaps: coarse_max_iterations must be >= 1, got " +
                std::to_string(config.coarse_max_iterations));
  }
  if (!(config.coarse_tolerance_scale >= 1.0)) {
    throw Error("align_submaps: coarse_tolerance_scale must be >= 1, got " +
                std::to_string(config.coarse_tolerance_scale));
  }
  if (min_points_at_start_ > 0) {
    phase_ = Phase::kCountAtStart;
    request_ = RegistrationLmRequest{start_, 0, true};
  } else {
    begin_level(config.coarse_levels);
  }
}

void RegistrationLm::take(const RegistrationNormalEquations& sums) {
  if (done_) throw Error("RegistrationLm::take: the alignment has already finished");
  switch (phase_) {
    case Phase::kCountAtStart:
      outcome_.points_at_start = sums.used_points;
      if (sums.used_points < min_points_at_start_) {
        finish(RegistrationBatchOutcome::Status::kTooFewAtStart);
      } else {
        begin_level(config_.coarse_levels);
      }
      return;
    case Phase::kFirst:
      if (sums.used_points < config_.min_used_points) {
        fail_level("only " + std::to_string(sums.used_points) + " of " +
                   std::to_string(sums.used_points + sums.skipped_points) +
                   " registration points fall inside submap j's observed field (need " +
                   std::to_string(config_.min_used_points) +
                   "); the submaps do not overlap at this guess");
        return;
      }
      current_ = sums;
      level_initial_cost_ = sums.cost;
      plan_step();
      return;
    case Phase::kTrial:
      judge_trial(sums);
      return;
  }
}

void RegistrationLm::begin_level(int level) {
  level_ = level;
  pose_ = start_;
  lambda_ = config_.initial_lambda;
  iterations_ = 0;
  phase_ = Phase::kFirst;
  request_ = RegistrationLmRequest{start_, level, false};
}

void RegistrationLm::plan_step() {
  const int max_iterations = level_ > 0
                                 ? std::min(config_.coarse_max_iterations, config_.max_iterations)
                                 : config_.max_iterations;
  if (iterations_ >= max_iterations) {
    end_level(false);
    return;
  }
  ++iterations_;
  Eigen::Matrix4d damped = current_.hessian_i;
  for (int k = 0; k < 4; ++k) damped(k, k) += lambda_ * std::max(current_.hessian_i(k, k), 1e-12);
  step_ = damped.ldlt().solve(-current_.gradient_i);
  if (!step_.allFinite()) {
    fail_level(
        "the normal equations are singular (the overlap does not constrain all of x, y, z and "
        "yaw)");
    return;
  }
  Pose4Dof candidate = pose_;
  candidate.x += step_(0);
  candidate.y += step_(1);
  candidate.z += step_(2);
  candidate.yaw += step_(3);
  phase_ = Phase::kTrial;
  request_ = RegistrationLmRequest{candidate, level_, false};
}

void RegistrationLm::judge_trial(const RegistrationNormalEquations& trial) {
  const double current_mean = current_.cost / std::max<int64_t>(current_.used_points, 1);
  const double trial_mean = trial.cost / std::max<int64_t>(trial.used_points, 1);
  // A coarse level's cells span 2^level voxels: its tolerances grow with them.
  const double scale =
      level_ > 0 ? config_.coarse_tolerance_scale * static_cast<double>(1 << level_) : 1.0;
  const double translation_tolerance_m = config_.translation_tolerance_m * scale;
  const bool small_step = std::abs(step_(0)) < translation_tolerance_m &&
                          std::abs(step_(1)) < translation_tolerance_m &&
                          std::abs(step_(2)) < translation_tolerance_m &&
                          std::abs(step_(3)) < config_.yaw_tolerance_rad * scale;
  if (trial.used_points >= config_.min_used_points && trial_mean <= current_mean) {
    pose_ = request_.pose;
    current_ = trial;
    lambda_ = std::max(lambda_ / 3.0, 1e-9);
  } else {
    lambda_ *= 4.0;
  }
  // A small step ends the level either way: kept, it moved less than the tolerance; refused, no
  // smaller step can improve, so the pose is at the minimum to within the tolerance.
  if (small_step) {
    end_level(true);
  } else {
    plan_step();
  }
}

void RegistrationLm::end_level(bool converged) {
  if (level_ > 0) {
    start_ = pose_;
    coarse_iterations_ += iterations_;
    begin_level(level_ - 1);
    return;
  }
  RegistrationResult& result = outcome_.result;
  result.T_Sj_Si = pose_;
  result.initial_cost = level_initial_cost_;
  result.final_cost = current_.cost;
  result.iterations = iterations_ + coarse_iterations_;
  result.converged = converged;
  result.used_points = current_.used_points;
  result.skipped_points = current_.skipped_points;
  result.hessian = current_.hessian_i;
  finish(RegistrationBatchOutcome::Status::kAligned);
}

void RegistrationLm::fail_level(const std::string& why) {
  if (level_ > 0) {  // a coarse level that fails: the next starts where this one would have
    begin_level(level_ - 1);
    return;
  }
  outcome_.failure = "align_submaps: " + why;
  finish(RegistrationBatchOutcome::Status::kFailed);
}

void RegistrationLm::finish(RegistrationBatchOutcome::Status status) {
  outcome_.status = status;
  done_ = true;
}

}  // namespace backend
}  // namespace covox

#include "covoxslam/pipeline/registration_constraints.h"

#include <algorithm>
#include <cmath>
#include <exception>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

namespace {

void require(bool condition, const std::string& message) {
  if (!condition) throw Error("SLAM configuration: registration." + message);
}

bool positive_finite(double value) { return std::isfinite(value) && value > 0.0; }

}  // namespace

void validate(const SubmapRegistrationConfig& config) {
  require(std::isfinite(config.sampling_ratio) && config.sampling_ratio > 0.0f && config.sampling_ratio <= 1.0f,
          "sampling_ratio must be in (0, 1], got " + std::to_string(config.sampling_ratio));
  require(positive_finite(config.robust_loss_scale_m),
          "robust_loss_scale_m must be positive, got " + std::to_string(config.robust_loss_scale_m));
  require(positive_finite(config.point_sigma_m), "point_sigma_m must be positive, got " + std::to_string(config.point_sigma_m));
  require(config.min_shared_blocks >= 1, "min_shared_blocks must be at least 1, got " + std::to_string(config.min_shared_blocks));
  require(config.min_points >= 4, "min_points must be at least 4 (four unknowns), got " + std::to_string(config.min_points));
  require(positive_finite(config.max_correction_m),
          "max_correction_m must be positive, got " + std::to_string(config.max_correction_m));
  require(positive_finite(config.max_correction_rad) && config.max_correction_rad <= 3.14159265358979323846,
          "max_correction_rad must be in (0, pi], got " + std::to_string(config.max_correction_rad));
  require(config.max_partners >= 0, "max_partners must be >= 0, got " + std::to_string(config.max_partners));
  require(config.max_iterations >= 1, "max_iterations must be at least 1, got " + std::to_string(config.max_iterations));
}

backend::RobustLoss parse_robust_loss(const std::string& name) {
  if (name == "none") return backend::RobustLoss::kNone;
  if (name == "huber") return backend::RobustLoss::kHuber;
  if (name == "cauchy") return backend::RobustLoss::kCauchy;
  throw Error("registration: unknown robust_loss '" + name + "' (expected none, huber or cauchy)");
}

const char* to_string(backend::RobustLoss loss) {
  switch (loss) {
    case backend::RobustLoss::kNone: return "none";
    case backend::RobustLoss::kHuber: return "huber";
    case backend::RobustLoss::kCauchy: return "cauchy";
  }
  return "unknown";
}

backend::RegistrationDistance parse_registration_distance(const std::string& name) {
  if (name == "tsdf") return backend::RegistrationDistance::kTsdfNearSurface;
  if (name == "esdf") return backend::RegistrationDistance::kEsdf;
  throw Error("registration: unknown distance '" + name + "' (expected tsdf or esdf)");
}

const char* to_string(backend::RegistrationDistance distance) {
  switch (distance) {
    case backend::RegistrationDistance::kTsdfNearSurface: return "tsdf";
    case backend::RegistrationDistance::kEsdf: return "esdf";
  }
  return "unknown";
}

void RegistrationCounts::add(const RegistrationCounts& other) {
  attempted += other.attempted;
  accepted += other.accepted;
  rejected_failed += other.rejected_failed;
  rejected_too_far += other.rejected_too_far;
  rejected_too_few_points += other.rejected_too_few_points;
}

std::unique_ptr<SubmapRegistrationPoints> prepare_registration_points(const TsdfMap& map,
                                                                     const SubmapRegistrationConfig& config,
                                                                     const Stream& stream) {
  auto result = std::make_unique<SubmapRegistrationPoints>(map.device());
  backend::RegistrationPointsConfig points_config;
  points_config.sampling_ratio = config.sampling_ratio;
  result->points = backend::extract_registration_points(map, points_config, stream);
  // The mean weight needs the points on the host once (thousands of them: negligible).
  const std::vector<backend::RegistrationPoint> host = result->points.points.to_host(stream);
  double sum = 0.0;
  for (const backend::RegistrationPoint& p : host) sum += p.weight;
  result->mean_weight = host.empty() || !(sum > 0.0) ? 1.0 : sum / static_cast<double>(host.size());
  return result;
}

std::vector<SubmapConstraint> registration_constraints(int64_t id, const TsdfMap& map,
                                                       const SubmapRegistrationPoints& points,
                                                       const backend::Pose4Dof& pose,
                                                       const std::vector<RegistrationPartner>& earlier,
                                                       const SubmapRegistrationConfig& config, const Stream& stream,
                                                       RegistrationCounts* counts) {
  std::vector<SubmapConstraint> constraints;
  if (!config.enabled) return constraints;

  // Overlapping partners, most shared blocks first.
  struct Candidate {
    const RegistrationPartner* partner;
    int64_t shared_blocks;
  };
  std::vector<Candidate> candidates;
  for (const RegistrationPartner& partner : earlier) {
    const backend::SubmapOverlap overlap =
        backend::submap_overlap(map, pose, *partner.map, partner.pose, config.min_shared_blocks);
    if (overlap.overlapping) candidates.push_back(Candidate{&partner, overlap.shared_blocks});
  }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const Candidate& a, const Candidate& b) { return a.shared_blocks > b.shared_blocks; });
  if (config.max_partners > 0 && candidates.size() > static_cast<size_t>(config.max_partners)) {
    candidates.resize(static_cast<size_t>(config.max_partners));
  }

  backend::RegistrationAlignerConfig aligner;
  aligner.residual.distance = config.distance;
  aligner.residual.loss = config.robust_loss;
  // Weights normalised to mean 1 (see the header): metres become residual units by sqrt(mean w).
  const double sqrt_mean_weight = std::sqrt(points.mean_weight);
  aligner.residual.loss_scale = config.robust_loss_scale_m * sqrt_mean_weight;
  aligner.max_iterations = config.max_iterations;
  aligner.min_used_points = config.min_points;
  const backend::Pose4Dof identity;

  for (const Candidate& candidate : candidates) {
    const RegistrationPartner& partner = *candidate.partner;
    ++counts->attempted;
    const backend::Pose4Dof initial = relative_pose_4dof(partner.pose, pose);  // T_Sj_Si
    if (points.points.points.size() < static_cast<size_t>(config.min_points)) {
      ++counts->rejected_too_few_points;
      continue;
    }
    const backend::RegistrationNormalEquations at_start =
        backend::registration_normal_equations(points.points, *partner.map, initial, identity, aligner.residual, stream);
    if (at_start.used_points < config.min_points) {
      ++counts->rejected_too_few_points;
      continue;
    }
    backend::RegistrationResult result;
    try {
      result = backend::align_submaps(points.points, *partner.map, initial, aligner, stream);
    } catch (const std::exception& error) {
      ++counts->rejected_failed;
      log_message(LogLevel::kDebug, "SLAM registration: aligning submap ", id, " to ", partner.id, " failed: ", error.what());
      continue;
    }
    if (!result.converged) {
      ++counts->rejected_failed;
      continue;
    }
    if (result.used_points < config.min_points) {
      ++counts->rejected_too_few_points;
      continue;
    }
    const Eigen::Vector3d moved(result.T_Sj_Si.x - initial.x, result.T_Sj_Si.y - initial.y,
                                result.T_Sj_Si.z - initial.z);
    const double turned = std::abs(std::atan2(std::sin(result.T_Sj_Si.yaw - initial.yaw),
                                              std::cos(result.T_Sj_Si.yaw - initial.yaw)));
    if (!(moved.norm() <= config.max_correction_m) || !(turned <= config.max_correction_rad)) {
      ++counts->rejected_too_far;
      log_message(LogLevel::kDebug, "SLAM registration: rejected submap ", id, " to ", partner.id, ": moved ", moved.norm(), " m and ",
                turned, " rad from the guess");
      continue;
    }
    // The backend's constraint (information = hessian / sigma^2, here sigma in residual units),
    // read back as an information matrix S^T S for the submap-level graph.
    const backend::Constraint4Dof constraint =
        backend::make_registration_constraint(0, 1, result, config.point_sigma_m * sqrt_mean_weight);
    const Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> sqrt_information(constraint.sqrt_information);
    SubmapConstraint c;
    c.kind = SubmapConstraintKind::kRegistration;
    c.from_submap = partner.id;
    c.to_submap = id;
    c.measurement = constraint.measurement;
    c.information = sqrt_information.transpose() * sqrt_information;
    constraints.push_back(c);
    ++counts->accepted;
  }
  return constraints;
}

}  // namespace pipeline
}  // namespace covox

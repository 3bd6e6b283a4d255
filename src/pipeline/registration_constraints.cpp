#include "covoxslam/pipeline/registration_constraints.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <exception>
#include <memory>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/pipeline/submap.h"
#include "covoxslam/pipeline/wall_map.h"

namespace covox {
namespace pipeline {

namespace {

void require(bool condition, const std::string& message) {
  if (!condition) throw Error("SLAM configuration: registration." + message);
}

bool positive_finite(double value) { return std::isfinite(value) && value > 0.0; }

}  // namespace

void validate(const SubmapRegistrationConfig& config) {
  require(std::isfinite(config.sampling_ratio) && config.sampling_ratio > 0.0f &&
              config.sampling_ratio <= 1.0f,
          "sampling_ratio must be in (0, 1], got " + std::to_string(config.sampling_ratio));
  require(
      positive_finite(config.robust_loss_scale_m),
      "robust_loss_scale_m must be positive, got " + std::to_string(config.robust_loss_scale_m));
  require(positive_finite(config.point_sigma_m),
          "point_sigma_m must be positive, got " + std::to_string(config.point_sigma_m));
  require(std::isfinite(config.min_sigma_m) && config.min_sigma_m >= 0.0,
          "min_sigma_m must be >= 0, got " + std::to_string(config.min_sigma_m));
  require(std::isfinite(config.min_sigma_yaw_rad) && config.min_sigma_yaw_rad >= 0.0,
          "min_sigma_yaw_rad must be >= 0, got " + std::to_string(config.min_sigma_yaw_rad));
  require(config.min_shared_blocks >= 1,
          "min_shared_blocks must be at least 1, got " + std::to_string(config.min_shared_blocks));
  require(config.min_points >= 4, "min_points must be at least 4 (four unknowns), got " +
                                      std::to_string(config.min_points));
  require(positive_finite(config.max_correction_m),
          "max_correction_m must be positive, got " + std::to_string(config.max_correction_m));
  require(
      positive_finite(config.max_correction_rad) &&
          config.max_correction_rad <= 3.14159265358979323846,
      "max_correction_rad must be in (0, pi], got " + std::to_string(config.max_correction_rad));
  require(positive_finite(config.inlier_distance_m),
          "inlier_distance_m must be positive, got " + std::to_string(config.inlier_distance_m));
  require(
      std::isfinite(config.min_inlier_fraction) && config.min_inlier_fraction >= 0.0 &&
          config.min_inlier_fraction <= 1.0,
      "min_inlier_fraction must be in [0, 1], got " + std::to_string(config.min_inlier_fraction));
  require(positive_finite(config.search_step_m),
          "search_step_m must be positive, got " + std::to_string(config.search_step_m));
  require(positive_finite(config.search_step_rad),
          "search_step_rad must be positive, got " + std::to_string(config.search_step_rad));
  require(std::isfinite(config.search_max_yaw_rad) && config.search_max_yaw_rad >= 0.0,
          "search_max_yaw_rad must be >= 0, got " + std::to_string(config.search_max_yaw_rad));
  require(config.min_fit_points >= 0,
          "min_fit_points must be >= 0, got " + std::to_string(config.min_fit_points));
  require(config.search_candidates >= 1,
          "search_candidates must be at least 1, got " + std::to_string(config.search_candidates));
  require(config.search_max_points >= 4,
          "search_max_points must be at least 4, got " + std::to_string(config.search_max_points));
  require(config.max_partners >= 0,
          "max_partners must be >= 0, got " + std::to_string(config.max_partners));
  require(config.max_iterations >= 1,
          "max_iterations must be at least 1, got " + std::to_string(config.max_iterations));
  require(
      std::isfinite(config.gate_worst_fraction) && config.gate_worst_fraction >= 0.0 &&
          config.gate_worst_fraction < 1.0,
      "gate_worst_fraction must be in [0, 1), got " + std::to_string(config.gate_worst_fraction));
  require(std::isfinite(config.max_graph_residual_m) && config.max_graph_residual_m >= 0.0,
          "max_graph_residual_m must be >= 0 (metres; 0: off), got " +
              std::to_string(config.max_graph_residual_m));
  require(config.revisit_min_id_gap >= 1, "revisit_min_id_gap must be at least 1, got " +
                                              std::to_string(config.revisit_min_id_gap));
  require(std::isfinite(config.wall_search_range_m) && config.wall_search_range_m >= 0.0,
          "wall_search_range_m must be >= 0, got " + std::to_string(config.wall_search_range_m));
  require(
      std::isfinite(config.wall_search_min_score) && config.wall_search_min_score >= 0.0,
      "wall_search_min_score must be >= 0, got " + std::to_string(config.wall_search_min_score));
  require(
      std::isfinite(config.wall_search_min_jump_m) && config.wall_search_min_jump_m >= 0.0,
      "wall_search_min_jump_m must be >= 0, got " + std::to_string(config.wall_search_min_jump_m));
  require(config.coarse_levels >= 0 && config.coarse_levels <= 6,
          "coarse_levels must be in [0, 6] (coarsest stride 2^6 voxels), got " +
              std::to_string(config.coarse_levels));
}

Eigen::Matrix4d floored_information(const Eigen::Matrix4d& points_information, double min_sigma_m,
                                    double min_sigma_yaw_rad) {
  if (!(min_sigma_m > 0.0) && !(min_sigma_yaw_rad > 0.0)) return points_information;
  const Eigen::Vector4d floor_variance(min_sigma_m * min_sigma_m, min_sigma_m * min_sigma_m,
                                       min_sigma_m * min_sigma_m,
                                       min_sigma_yaw_rad * min_sigma_yaw_rad);
  // With information = R R^T, R = V Lambda^(1/2) (its eigenvectors and eigenvalues),
  //   (information^-1 + F)^-1 = R (I + R^T F R)^-1 R^T,
  // which needs no inverse of the information: a free direction (eigenvalue 0) keeps zero
  // information instead of breaking the computation.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eigen(
      0.5 * (points_information + points_information.transpose()));
  const Eigen::Vector4d values = eigen.eigenvalues();
  const Eigen::Matrix4d& vectors = eigen.eigenvectors();
  Eigen::Vector4d root = Eigen::Vector4d::Zero();
  for (int k = 0; k < 4; ++k) root(k) = values(k) > 0.0 ? std::sqrt(values(k)) : 0.0;
  const Eigen::Matrix4d floor_in_basis =
      vectors.transpose() * floor_variance.asDiagonal() * vectors;
  const Eigen::Matrix4d m = root.asDiagonal() * floor_in_basis * root.asDiagonal();
  const Eigen::Matrix4d inner = (Eigen::Matrix4d::Identity() + m).inverse();
  const Eigen::Matrix4d result =
      vectors * root.asDiagonal() * inner * root.asDiagonal() * vectors.transpose();
  return 0.5 * (result + result.transpose());
}

backend::RobustLoss parse_robust_loss(const std::string& name) {
  if (name == "none") return backend::RobustLoss::kNone;
  if (name == "huber") return backend::RobustLoss::kHuber;
  if (name == "cauchy") return backend::RobustLoss::kCauchy;
  throw Error("registration: unknown robust_loss '" + name + "' (expected none, huber or cauchy)");
}

const char* to_string(backend::RobustLoss loss) {
  switch (loss) {
    case backend::RobustLoss::kNone:
      return "none";
    case backend::RobustLoss::kHuber:
      return "huber";
    case backend::RobustLoss::kCauchy:
      return "cauchy";
  }
  return "unknown";
}

RegistrationMode parse_registration_mode(const std::string& name) {
  if (name == "pairwise") return RegistrationMode::kPairwise;
  if (name == "joint") return RegistrationMode::kJoint;
  throw Error("registration: unknown mode '" + name + "' (expected pairwise or joint)");
}

const char* to_string(RegistrationMode mode) {
  return mode == RegistrationMode::kJoint ? "joint" : "pairwise";
}

backend::RegistrationDistance parse_registration_distance(const std::string& name) {
  if (name == "tsdf") return backend::RegistrationDistance::kTsdfNearSurface;
  if (name == "esdf") return backend::RegistrationDistance::kEsdf;
  throw Error("registration: unknown distance '" + name + "' (expected tsdf or esdf)");
}

const char* to_string(backend::RegistrationDistance distance) {
  switch (distance) {
    case backend::RegistrationDistance::kTsdfNearSurface:
      return "tsdf";
    case backend::RegistrationDistance::kEsdf:
      return "esdf";
  }
  return "unknown";
}

void RegistrationCounts::add(const RegistrationCounts& other) {
  attempted += other.attempted;
  accepted += other.accepted;
  rejected_failed += other.rejected_failed;
  rejected_too_far += other.rejected_too_far;
  rejected_too_few_points += other.rejected_too_few_points;
  rejected_poor_fit += other.rejected_poor_fit;
  found_by_search += other.found_by_search;
  started_from_walls += other.started_from_walls;
  joint_pairs += other.joint_pairs;
}

std::unique_ptr<SubmapRegistrationPoints> prepare_registration_points(
    const TsdfMap& map, const SubmapRegistrationConfig& config, const Stream& stream) {
  auto result = std::make_unique<SubmapRegistrationPoints>(map.device());
  backend::RegistrationPointsConfig points_config;
  points_config.sampling_ratio = config.sampling_ratio;
  result->points = backend::extract_registration_points(map, points_config, stream);
  // The mean weight needs the points on the host once (thousands of them: negligible).
  const std::vector<backend::RegistrationPoint> host = result->points.points.to_host(stream);
  double sum = 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  result->sqrt_weights.reserve(host.size());
  for (const backend::RegistrationPoint& p : host) {
    sum += p.weight;
    centroid += Eigen::Vector3d(p.position_m.x, p.position_m.y, p.position_m.z);
    result->sqrt_weights.push_back(std::sqrt(p.weight));
  }
  result->mean_weight = host.empty() || !(sum > 0.0) ? 1.0 : sum / static_cast<double>(host.size());
  if (!host.empty()) result->centroid_m = centroid / static_cast<double>(host.size());
  // An even subsample (every k-th point of the sorted order) for the revisit search.
  const size_t stride =
      std::max<size_t>(1, (host.size() + static_cast<size_t>(config.search_max_points) - 1) /
                              static_cast<size_t>(config.search_max_points));
  std::vector<backend::RegistrationPoint> subsample;
  for (size_t k = 0; k < host.size(); k += stride) {
    subsample.push_back(host[k]);
    result->search_sqrt_weights.push_back(result->sqrt_weights[k]);
  }
  result->search_points.points =
      Buffer<backend::RegistrationPoint>::from_host(map.device(), subsample, stream);
  result->search_points.surface_voxels = result->points.surface_voxels;
  return result;
}

namespace {

// How many of the points that fall into submap j's observed field lie near its surfaces,
// counted over the points whose distance field gradient is mostly horizontal (walls, poles,
// trunks): those are what fix x, y and yaw. Ground points fit at any horizontal offset and
// outnumber everything else in a LiDAR scan, so counting them would make any alignment look good.
struct Fit {
  int64_t used = 0;
  int64_t inliers = 0;
  double fraction() const {
    return used > 0 ? static_cast<double>(inliers) / static_cast<double>(used) : 0.0;
  }
};
// |horizontal gradient| above this (the surface normal within about 45 degrees of horizontal).
constexpr double kHorizontalGradient = 0.7;

Fit evaluate_fit(const backend::RegistrationPoints& points, const std::vector<float>& sqrt_weights,
                 const TsdfMap& map_j, const backend::Pose4Dof& T_Sj_Si,
                 const backend::RegistrationResidualConfig& residual, double inlier_distance_m,
                 Buffer<backend::RegistrationResidual>* scratch, const Stream& stream) {
  backend::evaluate_registration_residuals(points, map_j, T_Sj_Si, backend::Pose4Dof(), residual,
                                           scratch, stream);
  const std::vector<backend::RegistrationResidual> host = scratch->to_host(stream);
  Fit fit;
  for (size_t k = 0; k < host.size(); ++k) {
    if (!host[k].valid || !(sqrt_weights[k] > 0.0f)) continue;
    // Residuals and Jacobians carry sqrt(weight); the tests are in metres.
    const double horizontal =
        std::hypot(host[k].jacobian_i[0], host[k].jacobian_i[1]) / sqrt_weights[k];
    if (horizontal < kHorizontalGradient) continue;
    ++fit.used;
    if (std::abs(host[k].residual) <= inlier_distance_m * sqrt_weights[k]) ++fit.inliers;
  }
  return fit;
}

enum class Verdict { kAccepted, kFailed, kTooFar, kTooFewPoints, kPoorFit };

struct Attempt {
  Verdict verdict = Verdict::kFailed;
  backend::RegistrationResult result;
  Fit fit;
};

// One alignment from `start`, judged against the guess `initial`.
// `reverse`: the symmetric pair (registration.h) when the partner's points are used too, else null.
Attempt attempt_alignment(const SubmapRegistrationPoints& points, const TsdfMap& map_j,
                          const backend::Pose4Dof& initial, const backend::Pose4Dof& start,
                          const backend::RegistrationAlignerConfig& aligner,
                          const SubmapRegistrationConfig& config,
                          const backend::SymmetricRegistrationPair* reverse,
                          Buffer<backend::RegistrationResidual>* scratch, const Stream& stream) {
  Attempt attempt;
  const backend::RegistrationNormalEquations at_start = backend::registration_normal_equations(
      points.points, map_j, start, backend::Pose4Dof(), aligner.residual, stream);
  if (at_start.used_points < config.min_points) {
    attempt.verdict = Verdict::kTooFewPoints;
    return attempt;
  }
  try {
    attempt.result = reverse ? backend::align_submaps_symmetric(*reverse, start, aligner, stream)
                             : backend::align_submaps(points.points, map_j, start, aligner, stream);
  } catch (const std::exception& error) {
    log_message(LogLevel::kDebug, "SLAM registration: an alignment failed: ", error.what());
    attempt.verdict = Verdict::kFailed;
    return attempt;
  }
  if (!attempt.result.converged) {
    attempt.verdict = Verdict::kFailed;
    return attempt;
  }
  if (attempt.result.used_points < config.min_points) {
    attempt.verdict = Verdict::kTooFewPoints;
    return attempt;
  }
  const backend::Pose4Dof& found = attempt.result.T_Sj_Si;
  const Eigen::Vector3d moved(found.x - initial.x, found.y - initial.y, found.z - initial.z);
  const double turned =
      std::abs(std::remainder(found.yaw - initial.yaw, 2.0 * 3.14159265358979323846));
  if (!(moved.norm() <= config.max_correction_m) || !(turned <= config.max_correction_rad)) {
    attempt.verdict = Verdict::kTooFar;
    return attempt;
  }
  attempt.fit = evaluate_fit(points.points, points.sqrt_weights, map_j, found, aligner.residual,
                             config.inlier_distance_m, scratch, stream);
  // Too few wall-like points to judge x, y and yaw is a poor fit as well.
  attempt.verdict = attempt.fit.used >= config.min_fit_points &&
                            attempt.fit.fraction() >= config.min_inlier_fraction
                        ? Verdict::kAccepted
                        : Verdict::kPoorFit;
  return attempt;
}

// Start poses for the revisit search: the guess moved on a grid of horizontal offsets and yaws
// (the yaw turns submap i's content about its centroid, so yaw and offset stay independent),
// the best few by the fit of the subsampled points, at least a grid step apart.
std::vector<backend::Pose4Dof> search_starts(const SubmapRegistrationPoints& points,
                                             const TsdfMap& map_j, const backend::Pose4Dof& initial,
                                             const backend::RegistrationResidualConfig& residual,
                                             const SubmapRegistrationConfig& config,
                                             Buffer<backend::RegistrationResidual>* scratch,
                                             const Stream& stream) {
  struct Scored {
    backend::Pose4Dof pose;
    double dx, dy, dyaw;
    int64_t inliers;
  };
  const int steps_xy = static_cast<int>(std::floor(config.max_correction_m / config.search_step_m));
  const double yaw_range = std::min(config.max_correction_rad, config.search_max_yaw_rad);
  const int steps_yaw = static_cast<int>(std::floor(yaw_range / config.search_step_rad));
  const double c0 = std::cos(initial.yaw), s0 = std::sin(initial.yaw);
  // Submap i's centroid in frame j at the guess.
  const Eigen::Vector2d centre(initial.x + c0 * points.centroid_m.x() - s0 * points.centroid_m.y(),
                               initial.y + s0 * points.centroid_m.x() + c0 * points.centroid_m.y());
  std::vector<Scored> scored;
  for (int iy = -steps_yaw; iy <= steps_yaw; ++iy) {
    const double dyaw = iy * config.search_step_rad;
    const double c = std::cos(dyaw), s = std::sin(dyaw);
    const Eigen::Vector2d t(initial.x - centre.x(), initial.y - centre.y());
    const Eigen::Vector2d turned(c * t.x() - s * t.y() + centre.x(),
                                 s * t.x() + c * t.y() + centre.y());
    for (int ix = -steps_xy; ix <= steps_xy; ++ix) {
      for (int jy = -steps_xy; jy <= steps_xy; ++jy) {
        const double dx = ix * config.search_step_m, dy = jy * config.search_step_m;
        if (std::hypot(dx, dy) > config.max_correction_m) continue;
        backend::Pose4Dof candidate = initial;
        candidate.x = turned.x() + dx;
        candidate.y = turned.y() + dy;
        candidate.yaw = initial.yaw + dyaw;
        const Fit fit =
            evaluate_fit(points.search_points, points.search_sqrt_weights, map_j, candidate,
                         residual, config.inlier_distance_m, scratch, stream);
        scored.push_back(Scored{candidate, dx, dy, dyaw, fit.inliers});
      }
    }
  }
  std::stable_sort(scored.begin(), scored.end(),
                   [](const Scored& a, const Scored& b) { return a.inliers > b.inliers; });
  std::vector<backend::Pose4Dof> starts;
  std::vector<const Scored*> chosen;
  for (const Scored& candidate : scored) {
    if (static_cast<int>(starts.size()) >= config.search_candidates || candidate.inliers == 0)
      break;
    bool near_chosen = false;
    for (const Scored* other : chosen) {
      near_chosen =
          near_chosen || (std::hypot(candidate.dx - other->dx, candidate.dy - other->dy) <=
                              1.5 * config.search_step_m &&
                          std::abs(candidate.dyaw - other->dyaw) <= 1.5 * config.search_step_rad);
    }
    if (near_chosen) continue;
    chosen.push_back(&candidate);
    starts.push_back(candidate.pose);
  }
  return starts;
}

}  // namespace

std::vector<const RegistrationPartner*> overlapping_partners(
    const TsdfMap& map, const backend::Pose4Dof& pose,
    const std::vector<RegistrationPartner>& earlier, const SubmapRegistrationConfig& config) {
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
  std::stable_sort(
      candidates.begin(), candidates.end(),
      [](const Candidate& a, const Candidate& b) { return a.shared_blocks > b.shared_blocks; });
  if (config.max_partners > 0 && candidates.size() > static_cast<size_t>(config.max_partners)) {
    candidates.resize(static_cast<size_t>(config.max_partners));
  }
  std::vector<const RegistrationPartner*> partners;
  for (const Candidate& candidate : candidates) partners.push_back(candidate.partner);
  return partners;
}

std::vector<SubmapConstraint> registration_constraints(
    int64_t id, const TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<RegistrationPartner>& earlier,
    const SubmapRegistrationConfig& config, const Stream& stream, RegistrationCounts* counts,
    WallMapCache* own_walls) {
  std::vector<SubmapConstraint> constraints;
  if (!config.enabled) return constraints;

  const std::vector<const RegistrationPartner*> partners =
      overlapping_partners(map, pose, earlier, config);

  backend::RegistrationAlignerConfig aligner;
  aligner.residual.distance = config.distance;
  aligner.residual.loss = config.robust_loss;
  // Weights normalised to mean 1 (see the header): metres become residual units by sqrt(mean w).
  const double sqrt_mean_weight = std::sqrt(points.mean_weight);
  aligner.residual.loss_scale = config.robust_loss_scale_m * sqrt_mean_weight;
  aligner.max_iterations = config.max_iterations;
  aligner.min_used_points = config.min_points;
  aligner.coarse_levels = config.coarse_levels;
  Buffer<backend::RegistrationResidual> scratch(map.device());
  // Wall maps are built at the first revisit that needs them; without a caller's cache, the new
  // submap's lives for this call and a partner's for its pair.
  WallMapCache local_own_walls;
  WallMapCache* const walls_i = own_walls ? own_walls : &local_own_walls;

  for (const RegistrationPartner* partner_pointer : partners) {
    const RegistrationPartner& partner = *partner_pointer;
    ++counts->attempted;
    if (points.points.points.size() < static_cast<size_t>(config.min_points)) {
      ++counts->rejected_too_few_points;
      continue;
    }
    const backend::Pose4Dof initial = relative_pose_4dof(partner.pose, pose);  // T_Sj_Si
    // Symmetric: the partner's own registration points in the new submap's field as well, their
    // weights brought to the new submap's units (the ratio of the mean weights, see the header).
    std::unique_ptr<SubmapRegistrationPoints> prepared_partner_points;
    backend::SymmetricRegistrationPair pair;
    if (config.symmetric) {
      const SubmapRegistrationPoints* partner_points = partner.points;
      if (!partner_points) {
        prepared_partner_points = prepare_registration_points(*partner.map, config, stream);
        partner_points = prepared_partner_points.get();
      }
      pair.points_i = &points.points;
      pair.map_j = partner.map;
      pair.points_j = &partner_points->points;
      pair.map_i = &map;
      pair.reverse_weight_scale = points.mean_weight / partner_points->mean_weight;
    }
    const backend::SymmetricRegistrationPair* reverse = config.symmetric ? &pair : nullptr;
    backend::Pose4Dof start = initial;
    bool from_walls = false;
    if (config.revisit_wall_search && id - partner.id >= config.revisit_min_id_gap) {
      WallMapCache local_partner_walls;
      WallMapCache* const walls_j = partner.walls ? partner.walls : &local_partner_walls;
      WallSearchConfig search;
      search.range_m = config.wall_search_range_m;
      const WallMatch match = match_walls(walls_i->get(map, stream),
                                          walls_j->get(*partner.map, stream), initial, search);
      const double jump_m =
          std::hypot(match.T_fixed_moving.x - initial.x, match.T_fixed_moving.y - initial.y);
      if (match.score >= config.wall_search_min_score && jump_m > config.wall_search_min_jump_m) {
        start = match.T_fixed_moving;
        from_walls = true;
        log_message(LogLevel::kDebug, "SLAM registration: submap ", partner.id, " -> ", id,
                    ": the walls match ", jump_m, " m from the guess (score ", match.score, ")");
      }
    }
    Attempt best = attempt_alignment(points, *partner.map, initial, start, aligner, config, reverse,
                                     &scratch, stream);
    const Verdict direct_verdict = best.verdict;
    bool from_search = false;
    if (best.verdict != Verdict::kAccepted && config.search_enabled) {
      for (const backend::Pose4Dof& start : search_starts(
               points, *partner.map, initial, aligner.residual, config, &scratch, stream)) {
        Attempt attempt = attempt_alignment(points, *partner.map, initial, start, aligner, config,
                                            reverse, &scratch, stream);
        if (attempt.verdict != Verdict::kAccepted) continue;
        if (best.verdict != Verdict::kAccepted || attempt.fit.fraction() > best.fit.fraction()) {
          best = attempt;
          from_search = true;
        }
      }
    }
    if (best.verdict != Verdict::kAccepted) {
      // The reason of the alignment from the guess: what a user can act on.
      switch (direct_verdict) {
        case Verdict::kTooFar:
          ++counts->rejected_too_far;
          break;
        case Verdict::kTooFewPoints:
          ++counts->rejected_too_few_points;
          break;
        case Verdict::kPoorFit:
          ++counts->rejected_poor_fit;
          break;
        default:
          ++counts->rejected_failed;
          break;
      }
      log_message(LogLevel::kDebug, "SLAM registration: no constraint from submap ", partner.id,
                  " to ", id);
      continue;
    }
    if (from_search) ++counts->found_by_search;
    if (from_walls && !from_search) ++counts->started_from_walls;
    log_message(LogLevel::kDebug, "SLAM registration: submap ", partner.id, " -> ", id, ": ",
                best.fit.inliers, " of ", best.fit.used, " points fit",
                from_search ? " (found by the revisit search)" : "");
    // The backend's constraint (information = hessian / sigma^2, here sigma in residual units),
    // read back as an information matrix S^T S for the submap-level graph.
    const backend::Constraint4Dof constraint = backend::make_registration_constraint(
        0, 1, best.result, config.point_sigma_m * sqrt_mean_weight);
    const Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> sqrt_information(
        constraint.sqrt_information);
    SubmapConstraint c;
    c.kind = SubmapConstraintKind::kRegistration;
    c.from_submap = partner.id;
    c.to_submap = id;
    c.measurement = constraint.measurement;
    c.information = floored_information(sqrt_information.transpose() * sqrt_information,
                                        config.min_sigma_m, config.min_sigma_yaw_rad);
    constraints.push_back(c);
    ++counts->accepted;
  }
  return constraints;
}

}  // namespace pipeline
}  // namespace covox

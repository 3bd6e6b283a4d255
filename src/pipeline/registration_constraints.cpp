#include "covoxslam/pipeline/registration_constraints.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <exception>
#include <memory>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/registration_batch.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/core/stage_profiler.h"
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

namespace {

void validate_alignment(const SubmapRegistrationConfig::Alignment& config) {
  require(positive_finite(config.robust_loss_scale_m),
          "alignment.robust_loss_scale_m must be positive, got " +
              std::to_string(config.robust_loss_scale_m));
  require(config.max_iterations >= 1, "alignment.max_iterations must be at least 1, got " +
                                          std::to_string(config.max_iterations));
  require(config.coarse_levels >= 0 && config.coarse_levels <= 6,
          "alignment.coarse_levels must be in [0, 6] (coarsest stride 2^6 voxels), got " +
              std::to_string(config.coarse_levels));
}

void validate_acceptance(const SubmapRegistrationConfig::Acceptance& config) {
  require(config.min_points >= 4, "acceptance.min_points must be at least 4 (four unknowns), got " +
                                      std::to_string(config.min_points));
  require(positive_finite(config.max_correction_m),
          "acceptance.max_correction_m must be positive, got " +
              std::to_string(config.max_correction_m));
  require(positive_finite(config.max_correction_rad) &&
              config.max_correction_rad <= 3.14159265358979323846,
          "acceptance.max_correction_rad must be in (0, pi], got " +
              std::to_string(config.max_correction_rad));
  require(std::isfinite(config.max_residual_rms_vox) && config.max_residual_rms_vox >= 0.0,
          "acceptance.max_residual_rms_vox must be >= 0 (0: off), got " +
              std::to_string(config.max_residual_rms_vox));
}

void validate_information(const SubmapRegistrationConfig::Information& config) {
  require(
      positive_finite(config.point_sigma_m),
      "information.point_sigma_m must be positive, got " + std::to_string(config.point_sigma_m));
  require(std::isfinite(config.min_sigma_vox) && config.min_sigma_vox >= 0.0,
          "information.min_sigma_vox must be >= 0, got " + std::to_string(config.min_sigma_vox));
  require(std::isfinite(config.min_sigma_yaw_rad) && config.min_sigma_yaw_rad >= 0.0,
          "information.min_sigma_yaw_rad must be >= 0, got " +
              std::to_string(config.min_sigma_yaw_rad));
}

void validate_revisits(const SubmapRegistrationConfig::Revisits& config) {
  require(config.min_id_gap >= 1,
          "revisits.min_id_gap must be at least 1, got " + std::to_string(config.min_id_gap));
  require(std::isfinite(config.wall_search_range_m) && config.wall_search_range_m >= 0.0,
          "revisits.wall_search_range_m must be >= 0, got " +
              std::to_string(config.wall_search_range_m));
  require(std::isfinite(config.wall_search_min_score) && config.wall_search_min_score >= 0.0,
          "revisits.wall_search_min_score must be >= 0, got " +
              std::to_string(config.wall_search_min_score));
  require(std::isfinite(config.wall_search_min_jump_m) && config.wall_search_min_jump_m >= 0.0,
          "revisits.wall_search_min_jump_m must be >= 0, got " +
              std::to_string(config.wall_search_min_jump_m));
}

void validate_gate(const SubmapRegistrationConfig::Gate& config) {
  require(std::isfinite(config.max_residual_vox) && config.max_residual_vox >= 0.0,
          "gate.max_residual_vox must be >= 0 (voxels; 0: off), got " +
              std::to_string(config.max_residual_vox));
  require(std::isfinite(config.worst_fraction) && config.worst_fraction >= 0.0 &&
              config.worst_fraction < 1.0,
          "gate.worst_fraction must be in [0, 1), got " + std::to_string(config.worst_fraction));
}

}  // namespace

void validate(const SubmapRegistrationConfig& config) {
  require(std::isfinite(config.sampling.ratio) && config.sampling.ratio > 0.0f &&
              config.sampling.ratio <= 1.0f,
          "sampling.ratio must be in (0, 1], got " + std::to_string(config.sampling.ratio));
  require(config.overlap.min_shared_blocks >= 1,
          "overlap.min_shared_blocks must be at least 1, got " +
              std::to_string(config.overlap.min_shared_blocks));
  require(config.overlap.max_partners >= 0,
          "overlap.max_partners must be >= 0, got " + std::to_string(config.overlap.max_partners));
  require(config.overlap.max_visits == 0 || config.overlap.max_visits >= 2,
          "overlap.max_visits must be 0 (every visit) or at least 2 (the first and the current "
          "pass), got " +
              std::to_string(config.overlap.max_visits));
  validate_alignment(config.alignment);
  validate_acceptance(config.acceptance);
  validate_information(config.information);
  validate_revisits(config.revisits);
  validate_gate(config.gate);
  require(std::isfinite(config.verification.max_mahalanobis_sq) &&
              config.verification.max_mahalanobis_sq >= 0.0,
          "verification.max_mahalanobis_sq must be >= 0 (0: off), got " +
              std::to_string(config.verification.max_mahalanobis_sq));
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

double odometry_mahalanobis_sq(const backend::Pose4Dof& measured,
                               const RegistrationOdometry& odometry_j,
                               const RegistrationOdometry& odometry_i,
                               const Eigen::Matrix4d& points_information, double floor_m,
                               double floor_rad) {
  const backend::Pose4Dof expected = relative_pose_4dof(odometry_j.pose, odometry_i.pose);
  const Eigen::Vector4d error(
      measured.x - expected.x, measured.y - expected.y, measured.z - expected.z,
      std::remainder(measured.yaw - expected.yaw, 2.0 * 3.14159265358979323846));
  const double path_m = std::abs(odometry_i.path_m - odometry_j.path_m);
  const double sigma_m = odometry_i.drift_m_per_m * path_m + floor_m;
  const double sigma_rad = odometry_i.drift_rad_per_m * path_m + floor_rad;
  const Eigen::Vector4d odometry_variance(sigma_m * sigma_m, sigma_m * sigma_m, sigma_m * sigma_m,
                                          sigma_rad * sigma_rad);
  // The points' covariance (the pseudo-inverse of their information: a free direction adds
  // nothing, the odometry's variance bounds it) added to the odometry's.
  Eigen::Matrix4d covariance = odometry_variance.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eigen(
      0.5 * (points_information + points_information.transpose()));
  for (int k = 0; k < 4; ++k) {
    const double value = eigen.eigenvalues()(k);
    if (value > 0.0) {
      const Eigen::Vector4d v = eigen.eigenvectors().col(k);
      covariance += v * v.transpose() / value;
    }
  }
  return error.dot(covariance.ldlt().solve(error));
}

void RegistrationCounts::add(const RegistrationCounts& other) {
  attempted += other.attempted;
  accepted += other.accepted;
  rejected_failed += other.rejected_failed;
  rejected_too_far += other.rejected_too_far;
  rejected_too_few_points += other.rejected_too_few_points;
  rejected_misfit += other.rejected_misfit;
  rejected_by_odometry += other.rejected_by_odometry;
  started_from_walls += other.started_from_walls;
  joint_pairs += other.joint_pairs;
}

std::unique_ptr<SubmapRegistrationPoints> prepare_registration_points(
    const map::TsdfMap& map, const SubmapRegistrationConfig& config, const Stream& stream) {
  auto result = std::make_unique<SubmapRegistrationPoints>(map.device());
  backend::RegistrationPointsConfig points_config;
  points_config.sampling_ratio = config.sampling.ratio;
  result->points = backend::extract_registration_points(map, points_config, stream);
  // The mean weight needs the points on the host once (thousands of them: negligible).
  const std::vector<backend::RegistrationPoint> host = result->points.points.to_host(stream);
  double sum = 0.0;
  for (const backend::RegistrationPoint& p : host) sum += p.weight;
  result->mean_weight = host.empty() || !(sum > 0.0) ? 1.0 : sum / static_cast<double>(host.size());
  return result;
}

namespace {

enum class Verdict { kAccepted, kFailed, kTooFar, kTooFewPoints };

// The verdict on one alignment (registration_batch.h's outcome) against the guess `initial`.
Verdict judge_alignment(const backend::RegistrationBatchOutcome& outcome,
                        const backend::Pose4Dof& initial,
                        const SubmapRegistrationConfig::Acceptance& acceptance) {
  using Status = backend::RegistrationBatchOutcome::Status;
  if (outcome.status == Status::kTooFewAtStart) return Verdict::kTooFewPoints;
  if (outcome.status == Status::kFailed) {
    log_message(LogLevel::kDebug, "SLAM registration: an alignment failed: ", outcome.failure);
    return Verdict::kFailed;
  }
  if (!outcome.result.converged) return Verdict::kFailed;
  if (outcome.result.used_points < acceptance.min_points) return Verdict::kTooFewPoints;
  const backend::Pose4Dof& found = outcome.result.T_Sj_Si;
  const Eigen::Vector3d moved(found.x - initial.x, found.y - initial.y, found.z - initial.z);
  const double turned =
      std::abs(std::remainder(found.yaw - initial.yaw, 2.0 * 3.14159265358979323846));
  return moved.norm() <= acceptance.max_correction_m && turned <= acceptance.max_correction_rad
             ? Verdict::kAccepted
             : Verdict::kTooFar;
}

// What every pair of one new submap shares: the aligner's settings in the new submap's residual
// units, and the new submap's wall map.
struct PairContext {
  int64_t id;
  const map::TsdfMap* map;
  const SubmapRegistrationPoints* points;
  backend::Pose4Dof pose;
  const SubmapRegistrationConfig* config;
  const Stream* stream;
  backend::RegistrationAlignerConfig aligner;
  double sqrt_mean_weight;
  WallMapCache* walls_i;
  RegistrationOdometry odometry;
};

backend::RegistrationAlignerConfig aligner_config(const SubmapRegistrationConfig& config,
                                                  double sqrt_mean_weight) {
  backend::RegistrationAlignerConfig aligner;
  aligner.residual.distance = config.alignment.distance;
  aligner.residual.loss = config.alignment.robust_loss;
  // Weights normalised to mean 1 (see the header): metres become residual units by sqrt(mean w).
  aligner.residual.loss_scale = config.alignment.robust_loss_scale_m * sqrt_mean_weight;
  aligner.max_iterations = config.alignment.max_iterations;
  aligner.min_used_points = config.acceptance.min_points;
  aligner.coarse_levels = config.alignment.coarse_levels;
  return aligner;
}

// The start of a revisit's alignment: the walls' match when it is good and far from the guess,
// else the guess itself. `from_walls` tells which.
backend::Pose4Dof revisit_start(const PairContext& context, const RegistrationPartner& partner,
                                const backend::Pose4Dof& initial, bool* from_walls) {
  *from_walls = false;
  const SubmapRegistrationConfig::Revisits& revisits = context.config->revisits;
  if (!revisits.wall_search || context.id - partner.id < revisits.min_id_gap) return initial;
  WallMapCache local_partner_walls;
  WallMapCache* const walls_j = partner.walls ? partner.walls : &local_partner_walls;
  WallSearchConfig search;
  search.range_m = revisits.wall_search_range_m;
  const WallMatch match =
      match_walls(context.walls_i->get(*context.map, *context.stream),
                  walls_j->get(*partner.map, *context.stream), initial, search, *context.stream);
  const double jump_m =
      std::hypot(match.T_fixed_moving.x - initial.x, match.T_fixed_moving.y - initial.y);
  if (!(match.score >= revisits.wall_search_min_score &&
        jump_m > revisits.wall_search_min_jump_m)) {
    return initial;
  }
  *from_walls = true;
  log_message(LogLevel::kDebug, "SLAM registration: submap ", partner.id, " -> ", context.id,
              ": the walls match ", jump_m, " m from the guess (score ", match.score, ")");
  return match.T_fixed_moving;
}

void count_rejection(Verdict verdict, RegistrationCounts* counts) {
  switch (verdict) {
    case Verdict::kTooFar:
      ++counts->rejected_too_far;
      break;
    case Verdict::kTooFewPoints:
      ++counts->rejected_too_few_points;
      break;
    default:
      ++counts->rejected_failed;
      break;
  }
}

// The constraint of an accepted alignment: the backend's constraint (information = hessian /
// sigma^2, here sigma in residual units), read back as an information matrix S^T S for the
// submap-level graph, with the accuracy floor.
SubmapConstraint accepted_constraint(const PairContext& context, int64_t partner_id,
                                     const backend::RegistrationResult& result) {
  const SubmapRegistrationConfig::Information& information = context.config->information;
  const backend::Constraint4Dof constraint = backend::make_registration_constraint(
      0, 1, result, information.point_sigma_m * context.sqrt_mean_weight);
  const Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> sqrt_information(
      constraint.sqrt_information);
  SubmapConstraint c;
  c.kind = SubmapConstraintKind::kRegistration;
  c.from_submap = partner_id;
  c.to_submap = context.id;
  c.measurement = constraint.measurement;
  c.information = floored_information(sqrt_information.transpose() * sqrt_information,
                                      information.min_sigma_vox * context.map->voxel_size_m(),
                                      information.min_sigma_yaw_rad);
  return c;
}

// The squared Mahalanobis distance of an accepted alignment from the odometry
// (odometry_mahalanobis_sq), with a floor of one voxel and one degree; -1 when either submap's
// odometry is unknown.
double verified_mahalanobis_sq(const PairContext& context, const RegistrationPartner& partner,
                               const SubmapConstraint& constraint) {
  if (!context.odometry.known || !partner.odometry.known) return -1.0;
  const double one_degree_rad = 3.14159265358979323846 / 180.0;
  return odometry_mahalanobis_sq(constraint.measurement, partner.odometry, context.odometry,
                                 constraint.information, context.map->voxel_size_m(),
                                 one_degree_rad);
}

// What every pair of the new submap `id` shares: its map, points, pose, settings and walls.
PairContext pair_context(int64_t id, const map::TsdfMap& map,
                         const SubmapRegistrationPoints& points, const backend::Pose4Dof& pose,
                         const SubmapRegistrationConfig& config, const Stream& stream,
                         WallMapCache* walls, const RegistrationOdometry& odometry) {
  const double sqrt_mean_weight = std::sqrt(points.mean_weight);
  return PairContext{id,
                     &map,
                     &points,
                     pose,
                     &config,
                     &stream,
                     aligner_config(config, sqrt_mean_weight),
                     sqrt_mean_weight,
                     walls,
                     odometry};
}

// A pair ready for the batched alignment: its guess, its start and its points.
struct PreparedPair {
  const RegistrationPartner* partner = nullptr;
  backend::Pose4Dof initial;  // the guess T_Sj_Si the result is judged against
  bool from_walls = false;
  std::unique_ptr<SubmapRegistrationPoints> partner_points;  // prepared here when not kept
  backend::RegistrationBatchPair batch;
};

// The guess (`guess`, or the current poses' relative pose), the start (from the walls on a
// revisit) and, when symmetric, the partner's points with their weights brought to the new
// submap's units (the ratio of the mean weights, see the header).
PreparedPair prepare_pair(const PairContext& context, const RegistrationPartner& partner,
                          const backend::Pose4Dof* guess) {
  PreparedPair prepared;
  prepared.partner = &partner;
  prepared.initial = guess ? *guess : relative_pose_4dof(partner.pose, context.pose);
  prepared.batch.points_i = &context.points->points;
  prepared.batch.map_j = partner.map;
  if (context.config->alignment.symmetric) {
    const SubmapRegistrationPoints* partner_points = partner.points;
    if (!partner_points) {
      prepared.partner_points =
          prepare_registration_points(*partner.map, *context.config, *context.stream);
      partner_points = prepared.partner_points.get();
    }
    prepared.batch.points_j = &partner_points->points;
    prepared.batch.map_i = context.map;
    prepared.batch.reverse_weight_scale = context.points->mean_weight / partner_points->mean_weight;
  }
  prepared.batch.start_T_Sj_Si =
      revisit_start(context, partner, prepared.initial, &prepared.from_walls);
  return prepared;
}

// An aligned pair judged and counted; true with `constraint` when accepted.
bool accept_pair(const PairContext& context, const PreparedPair& pair,
                 const backend::RegistrationBatchOutcome& outcome, RegistrationCounts* counts,
                 SubmapConstraint* constraint) {
  const SubmapRegistrationConfig& config = *context.config;
  const RegistrationPartner& partner = *pair.partner;
  const Verdict verdict = judge_alignment(outcome, pair.initial, config.acceptance);
  if (verdict != Verdict::kAccepted) {
    count_rejection(verdict, counts);
    log_message(LogLevel::kDebug, "SLAM registration: no constraint from submap ", partner.id,
                " to ", context.id);
    return false;
  }
  const backend::RegistrationResult& result = outcome.result;
  *constraint = accepted_constraint(context, partner.id, result);
  const double mahalanobis_sq = verified_mahalanobis_sq(context, partner, *constraint);
  const double rms =
      result.used_points > 0
          ? std::sqrt(2.0 * result.final_cost / static_cast<double>(result.used_points)) /
                context.sqrt_mean_weight
          : 0.0;
  log_message(LogLevel::kDebug, "SLAM registration: submap ", partner.id, " -> ", context.id,
              ": points ", result.used_points, " skipped ", result.skipped_points, " rms_m ", rms,
              " walls ", pair.from_walls, " mahalanobis_sq ", mahalanobis_sq);
  const double max_rms_vox = config.acceptance.max_residual_rms_vox;
  if (max_rms_vox > 0.0 && rms > max_rms_vox * context.map->voxel_size_m()) {
    ++counts->rejected_misfit;
    return false;
  }
  const double max_mahalanobis_sq = config.verification.max_mahalanobis_sq;
  if (max_mahalanobis_sq > 0.0 && mahalanobis_sq > max_mahalanobis_sq) {
    ++counts->rejected_by_odometry;
    return false;
  }
  if (pair.from_walls) ++counts->started_from_walls;
  ++counts->accepted;
  return true;
}

// The new submap against each partner: every pair prepared, then all aligned in lock step
// (registration_batch.h), then each judged. `guesses`: each pair's relative pose T_Sj_Si to
// start from; empty: the current poses' relative poses. Returns the accepted constraints.
std::vector<SubmapConstraint> register_pairs(
    const PairContext& context, const std::vector<const RegistrationPartner*>& partners,
    const std::vector<backend::Pose4Dof>& guesses, RegistrationCounts* counts) {
  const SubmapRegistrationConfig& config = *context.config;
  std::vector<SubmapConstraint> constraints;
  counts->attempted += static_cast<int64_t>(partners.size());
  if (partners.empty()) return constraints;
  if (context.points->points.points.size() < static_cast<size_t>(config.acceptance.min_points)) {
    counts->rejected_too_few_points += static_cast<int64_t>(partners.size());
    return constraints;
  }
  StageProfiler::Scope profile("registration pairs", *context.stream);
  std::vector<PreparedPair> pairs;
  std::vector<backend::RegistrationBatchPair> batch;
  for (size_t k = 0; k < partners.size(); ++k) {
    pairs.push_back(prepare_pair(context, *partners[k], guesses.empty() ? nullptr : &guesses[k]));
    batch.push_back(pairs.back().batch);
  }
  profile.mark("partner points and walls");
  const std::vector<backend::RegistrationBatchOutcome> outcomes = backend::align_submap_pairs(
      batch, context.aligner, *context.stream, config.acceptance.min_points);
  profile.mark("align");
  for (size_t k = 0; k < pairs.size(); ++k) {
    SubmapConstraint constraint;
    if (accept_pair(context, pairs[k], outcomes[k], counts, &constraint)) {
      constraints.push_back(constraint);
    }
  }
  return constraints;
}

struct PartnerCandidate {
  const RegistrationPartner* partner;
  int64_t shared_blocks;
};

// Leaves the candidates of the first visit and of the latest max_visits - 1 (overlap.max_visits),
// in increasing id order. Visits: runs of candidates whose consecutive ids differ by at most
// revisits.min_id_gap.
void keep_first_and_latest_visits(const SubmapRegistrationConfig& config,
                                  std::vector<PartnerCandidate>* candidates) {
  const int max_visits = config.overlap.max_visits;
  if (max_visits <= 0 || candidates->empty()) return;
  std::stable_sort(candidates->begin(), candidates->end(),
                   [](const PartnerCandidate& a, const PartnerCandidate& b) {
                     return a.partner->id < b.partner->id;
                   });
  std::vector<size_t> visit_starts = {0};
  for (size_t k = 1; k < candidates->size(); ++k) {
    if ((*candidates)[k].partner->id - (*candidates)[k - 1].partner->id >
        config.revisits.min_id_gap)
      visit_starts.push_back(k);
  }
  const size_t visits = visit_starts.size();
  if (visits <= static_cast<size_t>(max_visits)) return;
  // The first visit ends where the second starts; the latest ones begin at this visit.
  const size_t first_end = visit_starts[1];
  const size_t latest_begin = visit_starts[visits - static_cast<size_t>(max_visits - 1)];
  candidates->erase(candidates->begin() + static_cast<std::ptrdiff_t>(first_end),
                    candidates->begin() + static_cast<std::ptrdiff_t>(latest_begin));
}

}  // namespace

std::vector<const RegistrationPartner*> overlapping_partners(
    const map::TsdfMap& map, const backend::Pose4Dof& pose,
    const std::vector<RegistrationPartner>& earlier, const SubmapRegistrationConfig& config,
    const backend::SubmapFootprint* footprint) {
  using Candidate = PartnerCandidate;
  std::vector<Candidate> candidates;
  if (earlier.empty()) return {};
  // Every test reads the new map's blocks: exported once here unless the caller has them. A
  // partner without a kept footprint gets one for its test only.
  backend::SubmapFootprint own;
  if (!footprint) {
    own = backend::submap_footprint(map);
    footprint = &own;
  }
  for (const RegistrationPartner& partner : earlier) {
    backend::SubmapFootprint partner_own;
    const backend::SubmapFootprint* partner_footprint = partner.footprint;
    if (!partner_footprint) {
      partner_own = backend::submap_footprint(*partner.map);
      partner_footprint = &partner_own;
    }
    const backend::SubmapOverlap overlap = backend::submap_overlap(
        *footprint, pose, *partner_footprint, partner.pose, config.overlap.min_shared_blocks);
    if (overlap.overlapping) candidates.push_back(Candidate{&partner, overlap.shared_blocks});
  }
  keep_first_and_latest_visits(config, &candidates);
  std::stable_sort(
      candidates.begin(), candidates.end(),
      [](const Candidate& a, const Candidate& b) { return a.shared_blocks > b.shared_blocks; });
  const int max_partners = config.overlap.max_partners;
  if (max_partners > 0 && candidates.size() > static_cast<size_t>(max_partners)) {
    candidates.resize(static_cast<size_t>(max_partners));
  }
  std::vector<const RegistrationPartner*> partners;
  for (const Candidate& candidate : candidates) partners.push_back(candidate.partner);
  return partners;
}

std::vector<SubmapConstraint> registration_constraints(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<RegistrationPartner>& earlier,
    const SubmapRegistrationConfig& config, const Stream& stream, RegistrationCounts* counts,
    WallMapCache* own_walls, const RegistrationOdometry& odometry,
    const backend::SubmapFootprint* footprint) {
  if (!config.enabled) return {};
  return registration_constraints_with(id, map, points, pose,
                                       overlapping_partners(map, pose, earlier, config, footprint),
                                       config, stream, counts, own_walls, odometry);
}

std::vector<SubmapConstraint> registration_constraints_with(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<const RegistrationPartner*>& partners,
    const SubmapRegistrationConfig& config, const Stream& stream, RegistrationCounts* counts,
    WallMapCache* own_walls, const RegistrationOdometry& odometry) {
  if (!config.enabled) return {};
  // Wall maps are built at the first revisit that needs them; without a caller's cache, the new
  // submap's lives for this call and a partner's for its pair.
  WallMapCache local_own_walls;
  const PairContext context = pair_context(id, map, points, pose, config, stream,
                                           own_walls ? own_walls : &local_own_walls, odometry);
  return register_pairs(context, partners, {}, counts);
}

bool registration_constraint_from_guess(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const RegistrationPartner& partner,
    const backend::Pose4Dof& T_Sj_Si_guess, const SubmapRegistrationConfig& config,
    const Stream& stream, RegistrationCounts* counts, WallMapCache* own_walls,
    const RegistrationOdometry& odometry, SubmapConstraint* constraint) {
  WallMapCache local_own_walls;
  const PairContext context = pair_context(id, map, points, pose, config, stream,
                                           own_walls ? own_walls : &local_own_walls, odometry);
  const std::vector<SubmapConstraint> accepted =
      register_pairs(context, {&partner}, {T_Sj_Si_guess}, counts);
  if (accepted.empty()) return false;
  *constraint = accepted.front();
  return true;
}

}  // namespace pipeline
}  // namespace covox

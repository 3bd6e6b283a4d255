#pragma once
// Registration constraints for a finished submap (paper III-F, voxgraph's explicit_to_implicit):
// the submap's registration points are aligned to every earlier submap it overlaps, starting from
// the relative pose of their current corrected poses, and each plausible alignment becomes a
// relative 4-DoF constraint from the earlier submap to the new one.
//
// Acceptance. An alignment can "converge" far from the truth: points that land in the earlier
// submap's free space read a flat, clamped ESDF and pull nowhere, and ground points fit at any
// horizontal offset. So besides the aligner's own verdict, an alignment must fit: of the points
// on wall-like surfaces (horizontal distance gradient) that fall into the earlier submap's
// observed field, at least min_fit_points must exist and min_inlier_fraction must lie within
// inlier_distance_m of its surfaces.
//
// Revisits. At a revisit the guess carries all the drift since the last visit (metres, degrees),
// outside the aligner's basin (about the ESDF range). When the alignment from the guess does not
// fit, a coarse search evaluates the fit on a grid of horizontal offsets and yaws within the
// plausible correction (max_correction_m, max_correction_rad) with a subsample of the points,
// and the aligner restarts from the best few candidates.
//
// Weights. The aligner's residuals are metres times sqrt(TSDF weight), and TSDF weights depend on
// the weighting scheme (constant, inverse square, sparsity compensation), so a sigma in those
// units would change meaning with the integrator settings. Here the weights are normalised to a
// mean of 1 over the submap's registration points: point_sigma_m is the noise of one point's
// distance in metres, the information is sum_k w_k/mean(w) J_k^T J_k / point_sigma_m^2, and the
// robust loss scale is in metres as well.
//
// Accuracy floor. That information treats thousands of points as independent, so it claims
// millimetres and hundredths of a degree. Measured on the simulated drone flight (2026-11-23,
// 256-column LiDAR, 0.2 m voxels; docs/benchmarks.md, "Drift correction on the simulated
// flight"): aligned from the true relative pose, 56 overlapping submap pairs end 0.24 m and 0.64
// degrees from it on average (the submaps' own drift, TSDF quantisation, sparse walls), about
// what the odometry drifts between two submaps. A constraint that claims 100 times more than it
// knows overrides the odometry and, at a revisit, pulls the whole graph. So the constraint's
// covariance is the points' covariance plus a floor: min_sigma_m on x, y and z and
// min_sigma_yaw_rad on yaw,
//   information = ((J^T J / sigma^2)^-1 + diag(min_sigma_m^2 x3, min_sigma_yaw_rad^2))^-1,
// which keeps the points' shape (a direction the overlap does not constrain - ground only: x, y
// and yaw - stays weak) but caps every direction at what the registration really achieves.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "covoxslam/backend/registration.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/tsdf_map.h"
#include "covoxslam/pipeline/submap_pose_graph.h"
#include "covoxslam/pipeline/wall_map.h"

namespace covox {
namespace pipeline {

// kPairwise: each overlapping pair is aligned once and summarised into one relative 4-DoF
// constraint (below). kJoint: voxgraph's joint optimisation - the pairs' point residuals enter the
// pose-graph solve itself as dense terms (backend/registration_terms.h) and are re-evaluated at
// every solver iteration. Pairs with a loaded submap stay pairwise in both modes (a loaded
// submap shares its vertex with the others, which the dense terms cannot express).
enum class RegistrationMode { kPairwise, kJoint };

struct SubmapRegistrationConfig {
  bool enabled = true;
  RegistrationMode mode = RegistrationMode::kPairwise;
  // Fraction of a submap's surface voxels used as registration points (voxgraph's 0.05).
  float sampling_ratio = 0.05f;
  // kTsdfNearSurface: sub-voxel TSDF distances near surfaces, ESDF beyond (see registration.h);
  // kEsdf: voxgraph's plain ESDF.
  backend::RegistrationDistance distance = backend::RegistrationDistance::kTsdfNearSurface;
  // Symmetric alignment (backend::align_submaps_symmetric): the earlier submap's registration
  // points are aligned into the new submap's field as well, in the same solve. Off by default
  // (voxgraph's one-way alignment); on in the ARCHE preset and config/arche.yaml (measured on the
  // simulated flight: docs/benchmarks.md, "Registration accuracy on the simulated flight").
  bool symmetric = false;
  backend::RobustLoss robust_loss = backend::RobustLoss::kNone;  // voxgraph uses none
  double robust_loss_scale_m = 0.1;
  // Noise of one registration point's distance (see above). The points of a 0.2 m map are not
  // independent (interpolation, one TSDF), so this is larger than the TSDF noise itself.
  double point_sigma_m = 0.1;
  // The accuracy floor (see above). 0 and 0 (the default): the points' information alone. The
  // ARCHE preset (tools/lib/slam_run.cpp) and config/arche.yaml use 0.2 m and 1 degree, the
  // accuracy measured at 0.2 m voxels; other voxel sizes and sensors need their own measurement.
  double min_sigma_m = 0.0;
  double min_sigma_yaw_rad = 0.0;
  // Overlap: block bounding boxes intersect at the current poses and at least this many block
  // centres of the new submap fall into blocks of the earlier one.
  int64_t min_shared_blocks = 4;
  // Fewer registration points inside the earlier submap's field: no constraint (counted).
  int64_t min_points = 100;
  // An alignment that moves the relative pose further than this from its starting guess is not
  // believed (counted): odometry does not drift that much between two looks at one place. This is
  // also the range of the revisit search.
  double max_correction_m = 2.0;
  double max_correction_rad = 0.349065850398866;  // 20 degrees
  // The fit test (see above).
  double inlier_distance_m = 0.3;
  // 0 and 0: off (the default). On the simulated drone flight (sparse walls above much ground)
  // the test rejected too many good consecutive alignments; see the report in the commit.
  double min_inlier_fraction = 0.0;
  int64_t min_fit_points = 0;
  // The coarse search for revisits (see above): grid steps, candidates refined, points used.
  // Off by default: on the simulated drone flight, wrong candidates won and cascaded.
  bool search_enabled = false;
  double search_step_m = 1.0;
  double search_step_rad = 0.0349065850398866;    // 2 degrees
  double search_max_yaw_rad = 0.174532925199433;  // 10 degrees (and at most max_correction_rad)
  int search_candidates = 3;
  int64_t search_max_points = 1500;
  // Revisit start from the walls (pipeline/wall_map.h): for pairs at least revisit_min_id_gap
  // submap ids apart, the top views' wall columns are matched over +-wall_search_range_m and
  // +-3 degrees around the guess, and when the best match has a score of at least
  // wall_search_min_score (about that many matched columns) and lies more than
  // wall_search_min_jump_m from the guess, the alignment starts there instead of at the guess.
  // Near the guess the aligner is better on its own (the wall match is only good to 0.1-0.5 m).
  // Off by default; on in the ARCHE preset.
  bool revisit_wall_search = false;
  int64_t revisit_min_id_gap = 4;
  double wall_search_range_m = 2.5;
  double wall_search_min_score = 50.0;
  double wall_search_min_jump_m = 0.5;
  // Align to at most this many earlier submaps (those sharing most blocks); 0: all.
  int max_partners = 10;
  int max_iterations = 60;
  // Coarse-to-fine alignment (backend::RegistrationAlignerConfig::coarse_levels): first on the
  // ESDF sampled every 2^coarse_levels voxels, halving down to 2, then the fine residual. A
  // revisit starts as far off as the drift since the last visit; the fine cost's basin is a few
  // decimetres. 0: off (the default).
  int coarse_levels = 0;
  // Consistency gate in the pose graph (SlamSystem's optimisation): after a solve, every
  // registration constraint whose measurement lies further than this (horizontal distance, m)
  // from the relative pose of its two submaps in the solution is set aside and the graph solved
  // again, until every remaining one agrees; each optimisation starts again from all of them, so a
  // constraint set aside earlier comes back once the graph agrees with it. A revisit that landed
  // in a wrong minimum of the registration cost (repeated structure) disagrees with the chain of
  // the other constraints by metres. 0: off (the default).
  double max_graph_residual_m = 0.0;
  // The gate's rounds set aside only the constraints further than this fraction of the largest
  // residual (and than max_graph_residual_m), the worst first: when wrong revisits pull the
  // solution, the right ones disagree with it too, and setting aside everything above the
  // threshold at once lost them with the wrong ones. In [0, 1); 0: all above the threshold at once.
  double gate_worst_fraction = 0.0;
};

// The information of a registration constraint: `points_information` (over x, y, z, yaw; may be
// singular where the overlap leaves a direction free) with the accuracy floor added to its
// covariance (see above). Zero floors return it unchanged.
Eigen::Matrix4d floored_information(const Eigen::Matrix4d& points_information, double min_sigma_m,
                                    double min_sigma_yaw_rad);

// Throws covox::Error naming the first invalid parameter (prefix "registration.").
void validate(const SubmapRegistrationConfig& config);

// "none", "huber" or "cauchy"; throws covox::Error naming the bad value otherwise.
backend::RobustLoss parse_robust_loss(const std::string& name);
const char* to_string(backend::RobustLoss loss);
// "pairwise" or "joint"; throws covox::Error naming the bad value otherwise.
RegistrationMode parse_registration_mode(const std::string& name);
const char* to_string(RegistrationMode mode);
// "tsdf" (kTsdfNearSurface) or "esdf"; throws covox::Error otherwise.
backend::RegistrationDistance parse_registration_distance(const std::string& name);
const char* to_string(backend::RegistrationDistance distance);

// A finished submap's registration points and the mean TSDF weight over them.
struct SubmapRegistrationPoints {
  explicit SubmapRegistrationPoints(Device device) : points(device), search_points(device) {}
  backend::RegistrationPoints points;
  double mean_weight = 1.0;
  std::vector<float> sqrt_weights;            // per point of `points`, on the host (fit test)
  backend::RegistrationPoints search_points;  // an even subsample for the revisit search
  std::vector<float> search_sqrt_weights;
  Eigen::Vector3d centroid_m = Eigen::Vector3d::Zero();  // of the points, in the submap frame
};
std::unique_ptr<SubmapRegistrationPoints> prepare_registration_points(
    const TsdfMap& map, const SubmapRegistrationConfig& config, const Stream& stream);

struct RegistrationCounts {
  int64_t attempted = 0;                // overlapping pairs aligned
  int64_t accepted = 0;                 // constraints added
  int64_t rejected_failed = 0;          // the aligner threw or did not converge
  int64_t rejected_too_far = 0;         // moved more than max_correction_m / _rad
  int64_t rejected_too_few_points = 0;  // fewer than min_points inside the partner's field
  int64_t rejected_poor_fit = 0;        // fewer than min_inlier_fraction of the points fit
  int64_t found_by_search = 0;          // accepted ones that needed the revisit search
  int64_t started_from_walls = 0;       // accepted revisits aligned from the wall match
  int64_t joint_pairs = 0;              // kJoint: overlapping pairs added as dense terms
  void add(const RegistrationCounts& other);
};

// An earlier submap to align to, at its current corrected pose.
struct RegistrationPartner {
  int64_t id = 0;
  const TsdfMap* map = nullptr;
  backend::Pose4Dof pose;
  WallMapCache* walls = nullptr;  // the map's wall map cache; null: built for each revisit
  // The map's registration points (prepare_registration_points with the same config), for the
  // reverse half of symmetric registration; null: prepared again for each pair.
  const SubmapRegistrationPoints* points = nullptr;
};

// The earlier submaps that overlap the new one at `pose` (bounding boxes, then shared blocks),
// most shared blocks first, at most max_partners.
std::vector<const RegistrationPartner*> overlapping_partners(
    const TsdfMap& map, const backend::Pose4Dof& pose,
    const std::vector<RegistrationPartner>& earlier, const SubmapRegistrationConfig& config);

// The constraints (kind kRegistration, from each partner to `id`) for the new submap at `pose`.
// `own_walls`: the new submap's wall map cache, kept by the caller for the revisits to come (null:
// built for this call only).
std::vector<SubmapConstraint> registration_constraints(
    int64_t id, const TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<RegistrationPartner>& earlier,
    const SubmapRegistrationConfig& config, const Stream& stream, RegistrationCounts* counts,
    WallMapCache* own_walls = nullptr);

}  // namespace pipeline
}  // namespace covox

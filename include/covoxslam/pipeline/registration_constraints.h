#pragma once
// Registration constraints for a finished submap (paper III-F, voxgraph's explicit_to_implicit):
// the submap's registration points are aligned to the earlier submaps it overlaps, starting from
// the relative pose of their current corrected poses, and each plausible alignment becomes a
// relative 4-DoF constraint from the earlier submap to the new one, its information floored at
// what a registration achieves (SubmapRegistrationConfig::Information). A revisit's guess
// carries all the drift since the last visit; the coarse-to-fine alignment and the start from
// the walls (pipeline/wall_map.h) widen the aligner's basin. docs/design.md ("Registration").
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

// The registration settings, grouped as in the configuration files (section `registration`;
// docs/parameters.md lists each with its unit and default).
struct SubmapRegistrationConfig {
  bool enabled = true;
  RegistrationMode mode = RegistrationMode::kPairwise;
  // Which earlier submaps a finished submap is aligned to.
  struct Overlap {
    // Block bounding boxes intersect at the current poses and at least this many block centres
    // of the new submap fall into blocks of the earlier one.
    int64_t min_shared_blocks = 4;
    // Align to at most this many earlier submaps (those sharing most blocks); 0: all.
    int max_partners = 10;
    // Align to the submaps of at most this many visits of the place: the first visit and the
    // latest ones (the current pass's own predecessors are the latest); 0: every visit. A visit
    // is a run of overlapping submaps whose ids are at most revisits.min_id_gap apart. Each
    // later pass was tied to the first and the previous passes when it was made, so the passes
    // in between add little, and on long missions they are the partners that have left the
    // memory budget and must be brought back.
    int max_visits = 3;
  } overlap;
  struct Sampling {
    // Fraction of a submap's surface voxels used as registration points (voxgraph's 0.05).
    float ratio = 0.05f;
  } sampling;
  // The aligner.
  struct Alignment {
    // kTsdfNearSurface: sub-voxel TSDF distances near surfaces, ESDF beyond (see registration.h);
    // kEsdf: voxgraph's plain ESDF.
    backend::RegistrationDistance distance = backend::RegistrationDistance::kTsdfNearSurface;
    // Symmetric alignment (backend::align_submaps_symmetric): the earlier submap's registration
    // points are aligned into the new submap's field as well, in the same solve (false:
    // voxgraph's one-way alignment).
    bool symmetric = true;
    backend::RobustLoss robust_loss = backend::RobustLoss::kNone;  // voxgraph uses none
    double robust_loss_scale_m = 0.1;
    int max_iterations = 60;
    // Coarse-to-fine alignment (backend::RegistrationAlignerConfig::coarse_levels): first on the
    // ESDF sampled every 2^coarse_levels voxels, halving down to 2, then the fine residual. A
    // revisit starts as far off as the drift since the last visit; the fine cost's basin is a
    // few voxels. 0: the fine residual only.
    int coarse_levels = 2;
  } alignment;
  // When an alignment becomes a constraint: the aligner converged with at least min_points points
  // inside the earlier submap's field and moved the relative pose no further from its guess than
  // odometry drifts between two looks at one place. Each rejection is counted.
  struct Acceptance {
    // Fewer registration points inside the earlier submap's field: no constraint.
    int64_t min_points = 100;
    // An alignment that moves the relative pose further than this from its starting guess is not
    // believed.
    double max_correction_m = 3.5;
    double max_correction_rad = 0.349065850398866;  // 20 degrees
    // The RMS of the aligned points' distances to the partner's surface (weights normalised to a
    // mean of 1), in voxels of the new submap. A right alignment leaves the surfaces' own noise,
    // under a voxel; one stuck in a wrong minimum (a repeated structure, a revisit started far
    // off) leaves surfaces apart by voxels. Above this, no constraint. 0: off.
    double max_residual_rms_vox = 1.0;
  } acceptance;
  // The constraint's information. The aligner's residuals are metres times sqrt(TSDF weight),
  // and TSDF weights depend on the weighting scheme, so the weights are normalised to a mean of 1
  // over the submap's registration points: the points' information is
  // sum_k w_k/mean(w) J_k^T J_k / point_sigma_m^2, and the robust loss scale is in metres too.
  // That treats thousands of points as independent and claims millimetres, while an alignment is
  // only as good as the submaps (their own drift, TSDF quantisation, sparse walls); a constraint
  // that claims far more than it knows overrides the odometry and, at a revisit, pulls the whole
  // graph. So a floor is added to the points' covariance:
  //   information = ((J^T J / sigma^2)^-1 + diag(s^2 x3, min_sigma_yaw_rad^2))^-1,
  // with s = min_sigma_vox x the voxel size,
  // which keeps the points' shape (a direction the overlap does not constrain - ground only: x, y
  // and yaw - stays weak) but caps every direction at what the registration really achieves.
  struct Information {
    // Noise of one registration point's distance. The points of a map are not independent
    // (interpolation, one TSDF), so this is larger than the TSDF noise itself.
    double point_sigma_m = 0.1;
    // The accuracy floor, in voxels of the new submap so that it scales with the map's
    // resolution (an alignment is as good as the TSDF it aligns to); 0 and 0: the points'
    // information alone.
    double min_sigma_vox = 1.0;
    double min_sigma_yaw_rad = 0.017453292519943295;  // 1 degree
  } information;
  // The start from the walls (pipeline/wall_map.h): for pairs at least min_id_gap submap ids
  // apart, the top views' wall columns are matched over +-wall_search_range_m and +-3 degrees
  // around the guess, and when the best match has a score of at least wall_search_min_score
  // (about that many matched columns) and lies more than wall_search_min_jump_m from the guess,
  // the alignment starts there instead of at the guess. Near the guess the aligner is better on
  // its own (the wall match is good to one or two wall-map cells).
  struct Revisits {
    bool wall_search = true;
    int64_t min_id_gap = 4;
    double wall_search_range_m = 2.5;
    double wall_search_min_score = 50.0;
    double wall_search_min_jump_m = 0.5;
  } revisits;
  // Consistency gate in the pose graph (SlamSystem's optimisation): after a solve, registration
  // constraints whose measurement lies further than max_residual_vox voxels (horizontal
  // distance) from the relative pose of their two submaps in the solution are set aside and the
  // graph solved again, until every remaining one agrees; each optimisation starts again from all
  // of them, so a constraint set aside earlier comes back once the graph agrees with it. A revisit
  // that landed in a wrong minimum of the registration cost (repeated structure) disagrees with
  // the chain of the other constraints by metres.
  struct Gate {
    // In voxels of the map, so that it scales with the resolution the registrations achieve;
    // 0: off.
    double max_residual_vox = 3.0;
    // Each round sets aside only the constraints further than this fraction of the largest
    // residual (and than max_residual_vox), the worst first: when wrong revisits pull the
    // solution, the right ones disagree with it too, and setting aside everything above the
    // threshold at once loses them with the wrong ones. In [0, 1); 0: all at once.
    double worst_fraction = 0.7;
  } gate;
  // Verification against the odometry (see odometry_mahalanobis below): an alignment whose
  // relative pose disagrees with the odometry's relative pose of the two submaps by more than the
  // odometry's own uncertainty along the path between them (plus the points' covariance and a
  // floor of one voxel and one degree) is not believed. The squared Mahalanobis distance of that
  // disagreement over (x, y, z, yaw) follows a chi-square law with 4 degrees of freedom when the
  // alignment is right; max_mahalanobis_sq is its threshold. 0: off.
  struct Verification {
    double max_mahalanobis_sq = 18.5;  // the 0.999 quantile
  } verification;
};

// What the odometry says about a submap: its odometry pose T_odom_S and the odometry's path
// length from the start of the run to the submap's first scan. Two submaps' odometry relative pose
// is believed to within drift_m_per_m (per axis) and drift_rad_per_m (yaw) times the path between
// them. `known` false: no verification for the pairs of this submap.
struct RegistrationOdometry {
  bool known = false;
  backend::Pose4Dof pose;
  double path_m = 0.0;
  double drift_m_per_m = 0.0;
  double drift_rad_per_m = 0.0;
};

// The squared Mahalanobis distance between the relative pose `measured` (T_Sj_Si) and the
// odometry's relative pose from `odometry_j` to `odometry_i`, under the covariance
//   diag((drift_m_per_m d + floor_m)^2 x3, (drift_rad_per_m d + floor_rad)^2) + points_covariance,
// d the path between the two submaps (drift rates of `odometry_i`). `points_information` may be
// singular (a free direction adds nothing).
double odometry_mahalanobis_sq(const backend::Pose4Dof& measured,
                               const RegistrationOdometry& odometry_j,
                               const RegistrationOdometry& odometry_i,
                               const Eigen::Matrix4d& points_information, double floor_m,
                               double floor_rad);

// The information of a registration constraint: `points_information` (over x, y, z, yaw; may be
// singular where the overlap leaves a direction free) with the accuracy floor added to its
// covariance (SubmapRegistrationConfig::Information). Zero floors return it unchanged.
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
  explicit SubmapRegistrationPoints(Device device) : points(device) {}
  backend::RegistrationPoints points;
  double mean_weight = 1.0;
};
std::unique_ptr<SubmapRegistrationPoints> prepare_registration_points(
    const map::TsdfMap& map, const SubmapRegistrationConfig& config, const Stream& stream);

struct RegistrationCounts {
  int64_t attempted = 0;                // overlapping pairs aligned
  int64_t accepted = 0;                 // constraints added
  int64_t rejected_failed = 0;          // the aligner threw or did not converge
  int64_t rejected_too_far = 0;         // moved more than max_correction_m / _rad
  int64_t rejected_too_few_points = 0;  // fewer than min_points inside the partner's field
  int64_t rejected_misfit = 0;          // residual RMS above max_residual_rms_vox
  int64_t rejected_by_odometry = 0;     // disagreed with the odometry (verification)
  int64_t started_from_walls = 0;       // accepted revisits aligned from the wall match
  int64_t joint_pairs = 0;              // kJoint: overlapping pairs added as dense terms
  void add(const RegistrationCounts& other);
};

// An earlier submap to align to, at its current corrected pose.
struct RegistrationPartner {
  int64_t id = 0;
  const map::TsdfMap* map = nullptr;
  backend::Pose4Dof pose;
  WallMapCache* walls = nullptr;  // the map's wall map cache; null: built for each revisit
  // The map's registration points (prepare_registration_points with the same config), for the
  // reverse half of symmetric registration; null: prepared again for each pair.
  const SubmapRegistrationPoints* points = nullptr;
  RegistrationOdometry odometry;  // for the verification; unknown: not verified
  // The map's blocks on the host (backend::submap_footprint), kept by the caller for the
  // overlap tests of every later submap; null: exported from the map at each test.
  const backend::SubmapFootprint* footprint = nullptr;
};

// The earlier submaps that overlap the new one at `pose` (bounding boxes, then shared blocks),
// those of the first and latest visits (overlap.max_visits), most shared blocks first, at most
// max_partners. `footprint`: the new map's, when the caller has it (null: computed here, once for
// all the earlier submaps).
std::vector<const RegistrationPartner*> overlapping_partners(
    const map::TsdfMap& map, const backend::Pose4Dof& pose,
    const std::vector<RegistrationPartner>& earlier, const SubmapRegistrationConfig& config,
    const backend::SubmapFootprint* footprint = nullptr);

// The constraints (kind kRegistration, from each partner to `id`) for the new submap at `pose`.
// `own_walls`: the new submap's wall map cache, kept by the caller for the revisits to come (null:
// built for this call only).
std::vector<SubmapConstraint> registration_constraints(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<RegistrationPartner>& earlier,
    const SubmapRegistrationConfig& config, const Stream& stream, RegistrationCounts* counts,
    WallMapCache* own_walls = nullptr, const RegistrationOdometry& odometry = {},
    const backend::SubmapFootprint* footprint = nullptr);

// The same for partners the caller has chosen already (overlapping_partners() with the same
// map, pose and config), so the overlap tests are not run twice.
std::vector<SubmapConstraint> registration_constraints_with(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<const RegistrationPartner*>& partners,
    const SubmapRegistrationConfig& config, const Stream& stream, RegistrationCounts* counts,
    WallMapCache* own_walls = nullptr, const RegistrationOdometry& odometry = {});

// One pair aligned from the relative pose `T_Sj_Si_guess` instead of the current poses' (place
// recognition's candidates), with the same start from the walls, acceptance tests, verification
// and counts as registration_constraints(); true with `constraint` when accepted.
bool registration_constraint_from_guess(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const RegistrationPartner& partner,
    const backend::Pose4Dof& T_Sj_Si_guess, const SubmapRegistrationConfig& config,
    const Stream& stream, RegistrationCounts* counts, WallMapCache* own_walls,
    const RegistrationOdometry& odometry, SubmapConstraint* constraint);

}  // namespace pipeline
}  // namespace covox

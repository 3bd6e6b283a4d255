#pragma once
// Submap-to-submap registration (paper III-F; voxgraph's `explicit_to_implicit`): registration
// points of submap i (its surface voxels, deterministically subsampled, kept on the device); per
// point p the residual r = sqrt(w) * (D_j(T_Sj^-1 T_Si p) - d_target), D_j the trilinearly
// interpolated distance field of submap j (RegistrationDistance), with analytic Jacobians with
// respect to both 4-DoF poses; a small Levenberg-Marquardt aligner over the relative pose (4x4
// system on the host, residuals and their J^T J reduction on the device; many pairs at once in
// registration_batch.h, which the aligners below run with one pair); an overlap test and the
// pose-graph constraint built from an alignment. docs/design.md ("Registration") has the rest.
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "covoxslam/backend/pose_graph_types.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/map/block_key_set.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace backend {

// One registration point in its submap's frame (device memory: trivially copyable).
struct RegistrationPoint {
  Vec3f position_m;              // voxel centre
  float tsdf_distance_m = 0.0f;  // the voxel's TSDF distance (target of kTsdfNearSurface)
  float weight = 0.0f;           // the voxel's TSDF weight
};

struct RegistrationPointsConfig {
  // A voxel is a surface voxel when |TSDF| < this many voxels and its weight >= min_weight.
  float surface_threshold_vox = 1.0f;
  float min_weight = 1e-4f;
  // Fraction of surface voxels kept (voxgraph's default 0.05). The choice is a hash of the voxel
  // index and the seed, so it is deterministic and identical on both backends.
  float sampling_ratio = 0.05f;
  uint32_t sampling_seed = 0;
};

struct RegistrationPoints {
  explicit RegistrationPoints(Device device = Device::kCpu) : points(device) {}
  Buffer<RegistrationPoint> points;  // sorted by block index, then voxel: backend independent
  int64_t surface_voxels = 0;        // surface voxels before sampling
};

// Throws covox::Error on a bad configuration.
RegistrationPoints extract_registration_points(const map::TsdfMap& map,
                                               const RegistrationPointsConfig& config,
                                               const Stream& stream);

enum class RobustLoss { kNone, kHuber, kCauchy };
// Why D_j is not always the plain ESDF: this library's ESDF is the exact distance to the nearest
// surface *site* (a voxel centre with |TSDF| <= site threshold), so it is zero on a band about
// two voxels thick and steps in whole voxels next to it, which would leave the aligner blind to
// sub-voxel offsets. With kTsdfNearSurface (the default) corners whose TSDF is observed and
// within `tsdf_band_m` of the surface use the TSDF distance (sub-voxel accurate), all others the
// ESDF (a far-field gradient that pulls large offsets in), and the point's own TSDF distance is
// the target (a voxel centre 3 cm in front of the surface should read 3 cm in submap j too), so
// points are not projected onto the isosurface. kEsdf is voxgraph's formulation: ESDF, target 0.
enum class RegistrationDistance { kEsdf, kTsdfNearSurface };

struct RegistrationResidualConfig {
  RegistrationDistance distance = RegistrationDistance::kTsdfNearSurface;
  // kTsdfNearSurface: TSDF values with |d| below this replace the ESDF at a corner. Keep it below
  // the truncation distance (TSDF values clamped at the truncation carry no distance).
  float tsdf_band_m = 0.2f;
  float min_tsdf_weight = 1e-4f;
  // Ceres' convention: cost = 0.5 rho(r^2) with scale a; Huber rho(s) = s (s <= a^2),
  // 2 a sqrt(s) - a^2 beyond; Cauchy rho(s) = a^2 log(1 + s / a^2). The scale is in residual
  // units, that is metres times sqrt(weight).
  RobustLoss loss = RobustLoss::kNone;
  double loss_scale = 0.1;
  // Corners of the distance field every this many voxels (1: the field's own resolution). Above
  // 1 the field is the ESDF alone, sampled on a grid that many times coarser and interpolated
  // trilinearly between those corners, with target 0: the TSDF is flat beyond its band and the
  // fine ESDF steps at voxel scale, so both trap an alignment that starts metres off; the coarse
  // ESDF is a smooth true distance whose slope reaches as far as esdf_max_distance_m. Used by the
  // aligner's coarse-to-fine levels (RegistrationAlignerConfig::coarse_levels).
  int32_t coarse_stride_vox = 1;
};

// Whether the residual's target is the point's own TSDF distance (kTsdfNearSurface at the
// field's own resolution) rather than 0 (the ESDF, or any coarse level).
bool registration_uses_tsdf_target(const RegistrationResidualConfig& config);

// The residual of one point and its Jacobians (already multiplied by sqrt(weight), not by the
// robust loss). `robust_weight` is rho'(r^2), the iteratively-reweighted least-squares weight.
struct RegistrationResidual {
  double residual = 0.0;
  double jacobian_i[4] = {};  // d r / d (x, y, z, yaw) of T_W_Si
  double jacobian_j[4] = {};  // d r / d (x, y, z, yaw) of T_W_Sj
  double robust_weight = 0.0;
  double cost = 0.0;  // 0.5 rho(r^2)
  uint8_t valid = 0;  // 0: the point fell outside submap j's observed field (skipped)
};

// Residuals of points of submap i (in map_j's device memory) against submap j.
void evaluate_registration_residuals(const RegistrationPoints& points_i, const map::TsdfMap& map_j,
                                     const Pose4Dof& T_W_Si, const Pose4Dof& T_W_Sj,
                                     const RegistrationResidualConfig& config,
                                     Buffer<RegistrationResidual>* residuals, const Stream& stream);
// Host convenience (tests).
std::vector<RegistrationResidual> evaluate_registration_residuals(
    const RegistrationPoints& points_i, const map::TsdfMap& map_j, const Pose4Dof& T_W_Si,
    const Pose4Dof& T_W_Sj, const RegistrationResidualConfig& config);

// Sums over the valid points, reduced on the device: the IRLS normal equations of pose i
// (pose j held fixed).
struct RegistrationNormalEquations {
  Eigen::Matrix4d hessian_i = Eigen::Matrix4d::Zero();   // sum rho' J_i^T J_i
  Eigen::Vector4d gradient_i = Eigen::Vector4d::Zero();  // sum rho' J_i^T r
  double cost = 0.0;                                     // sum 0.5 rho(r^2)
  int64_t used_points = 0;
  int64_t skipped_points = 0;  // outside submap j's observed field
};
RegistrationNormalEquations registration_normal_equations(
    const RegistrationPoints& points_i, const map::TsdfMap& map_j, const Pose4Dof& T_W_Si,
    const Pose4Dof& T_W_Sj, const RegistrationResidualConfig& config, const Stream& stream);

struct RegistrationAlignerConfig {
  RegistrationResidualConfig residual;
  int max_iterations = 60;
  double initial_lambda = 1e-3;  // LM damping relative to diag(H)
  // Converged when a step moves less than both. The cost is trilinear per cell and its point set
  // changes as points cross the edge of the other field's observed space, so near the minimum
  // most steps are refused and retried with more damping; much tighter tolerances only add such
  // rounds, not accuracy (a voxel is 0.1-0.2 m, a good alignment within a few centimetres).
  double translation_tolerance_m = 1e-4;
  double yaw_tolerance_rad = 1e-5;
  int64_t min_used_points = 50;  // fewer valid points: no overlap, fail
  // Coarse-to-fine: before the alignment with `residual`, align on the ESDF sampled every
  // 2^coarse_levels voxels, then every 2^(coarse_levels - 1), ..., 2 voxels (coarse_stride_vox of
  // registration.h), each level starting where the coarser one ended. 0: the fine level only.
  // A level that fails (too few points in the coarse field, singular) leaves the pose unchanged.
  int coarse_levels = 0;
  // A coarse level only has to bring the pose into the next level's basin: it ends after at most
  // coarse_max_iterations steps, or at tolerances coarse_tolerance_scale times the fine ones per
  // voxel of its stride (stride 4 and scale 10: 4 mm and 0.4 mrad over 0.1 mm and 0.01 mrad).
  int coarse_max_iterations = 15;
  double coarse_tolerance_scale = 10.0;
};

struct RegistrationResult {
  Pose4Dof T_Sj_Si;  // the relative pose found: x_Sj = Rz(yaw) x_Si + (x, y, z)
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;
  bool converged = false;
  int64_t used_points = 0;
  int64_t skipped_points = 0;
  Eigen::Matrix4d hessian = Eigen::Matrix4d::Zero();  // sum rho' J^T J at the solution
};

// Aligns submap i (its registration points) to submap j, starting at initial_T_Sj_Si.
// Throws covox::Error when fewer than min_used_points points overlap submap j's field.
RegistrationResult align_submaps(const RegistrationPoints& points_i, const map::TsdfMap& map_j,
                                 const Pose4Dof& initial_T_Sj_Si,
                                 const RegistrationAlignerConfig& config, const Stream& stream);

// Symmetric registration: besides submap i's points in submap j's field (above), submap j's
// points in submap i's field, both in one Levenberg-Marquardt over T_Sj_Si. Each direction has
// its own biases (the points of one submap, the unobserved corners and view-dependent TSDF of the
// other); in one solve over both, neither direction's biases decide the result alone.
struct SymmetricRegistrationPair {
  const RegistrationPoints* points_i = nullptr;
  const map::TsdfMap* map_j = nullptr;
  const RegistrationPoints* points_j = nullptr;  // on map_i's device
  const map::TsdfMap* map_i = nullptr;
  // The j-in-i terms (cost, gradient, Hessian) are multiplied by this, as if each of their
  // residuals were multiplied by its square root (the robust loss sees them so scaled too): it
  // brings the two submaps' TSDF weights to common units (the ratio of their mean weights).
  double reverse_weight_scale = 1.0;
};
// Sums over the relative pose T_Sj_Si of both directions (used_points counts both).
RegistrationNormalEquations symmetric_registration_normal_equations(
    const SymmetricRegistrationPair& pair, const Pose4Dof& T_Sj_Si,
    const RegistrationResidualConfig& config, const Stream& stream);
// As align_submaps, with both directions (min_used_points counts both). Throws covox::Error on a
// missing member or a bad reverse_weight_scale.
RegistrationResult align_submaps_symmetric(const SymmetricRegistrationPair& pair,
                                           const Pose4Dof& initial_T_Sj_Si,
                                           const RegistrationAlignerConfig& config,
                                           const Stream& stream);

// A relative 4-DoF constraint from j to i (measurement T_Sj_Si) for the pose-graph solver;
// information = hessian / residual_sigma^2 (the residual's noise in residual units).
Constraint4Dof make_registration_constraint(int32_t vertex_j, int32_t vertex_i,
                                            const RegistrationResult& result,
                                            double residual_sigma);

// Overlap of two submaps: their block bounding boxes (transformed into the world) intersect, and
// at least min_shared_blocks block centres of submap i fall into allocated blocks of submap j.
struct SubmapOverlap {
  bool bounding_boxes_intersect = false;
  int64_t shared_blocks = 0;
  bool overlapping = false;
};
SubmapOverlap submap_overlap(const map::TsdfMap& map_i, const Pose4Dof& T_W_Si,
                             const map::TsdfMap& map_j, const Pose4Dof& T_W_Sj,
                             int64_t min_shared_blocks);

// What submap_overlap reads from a map, on the host: its allocated block indices, their keys as
// a set, and the block-index bounding box. A finished submap's blocks never change, so its
// footprint is computed once and every later overlap test is host arithmetic on it, with no
// export of the map's hash table.
struct SubmapFootprint {
  double block_size_m = 0.0;
  std::vector<Index3D> blocks;
  map::BlockKeySet keys;         // pack_block_key of each block
  Index3D block_min, block_max;  // inclusive; meaningless when `blocks` is empty
};
SubmapFootprint submap_footprint(const map::TsdfMap& map);
// The same test as above on footprints; the same result for the same maps.
SubmapOverlap submap_overlap(const SubmapFootprint& footprint_i, const Pose4Dof& T_W_Si,
                             const SubmapFootprint& footprint_j, const Pose4Dof& T_W_Sj,
                             int64_t min_shared_blocks);

}  // namespace backend
}  // namespace covox

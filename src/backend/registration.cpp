#include "covoxslam/backend/registration.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <string>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/registration_batch.h"
#include "covoxslam/backend/internal/registration_ops.h"
#include "covoxslam/core/error.h"
#include "covoxslam/map/block_key.h"

namespace covox {
namespace backend {
namespace {

void check_finite_pose(const Pose4Dof& pose, const char* what) {
  if (!(std::isfinite(pose.x) && std::isfinite(pose.y) && std::isfinite(pose.z) &&
        std::isfinite(pose.yaw))) {
    throw Error(std::string("registration: pose ") + what + " is not finite");
  }
}

void check_same_device(const RegistrationPoints& points_i, const map::TsdfMap& map_j) {
  if (points_i.points.device() != map_j.device()) {
    throw Error(std::string("registration: the points of submap i live on ") +
                to_string(points_i.points.device()) + " but submap j on " +
                to_string(map_j.device()) + "; extract them from a map on the same device");
  }
}

}  // namespace

void validate_registration_residual_config(const RegistrationResidualConfig& config) {
  if (!(config.tsdf_band_m >= 0.0f) || !std::isfinite(config.tsdf_band_m)) {
    throw Error("registration: tsdf_band_m must be finite and >= 0, got " +
                std::to_string(config.tsdf_band_m));
  }
  if (config.coarse_stride_vox < 1 || config.coarse_stride_vox > 1024) {
    throw Error("registration: coarse_stride_vox must be in [1, 1024], got " +
                std::to_string(config.coarse_stride_vox));
  }
  if (config.loss != RobustLoss::kNone &&
      !(config.loss_scale > 0.0 && std::isfinite(config.loss_scale))) {
    throw Error("registration: a robust loss needs a finite loss_scale > 0, got " +
                std::to_string(config.loss_scale));
  }
}

RegistrationNormalEquations normal_equations_from_sums(const double* upper_hessian,
                                                       const double* gradient, double cost,
                                                       int64_t used_points, int64_t points) {
  RegistrationNormalEquations out;
  int k = 0;
  for (int row = 0; row < 4; ++row) {
    for (int col = row; col < 4; ++col) {
      out.hessian_i(row, col) = upper_hessian[k];
      out.hessian_i(col, row) = upper_hessian[k];
      ++k;
    }
    out.gradient_i(row) = gradient[row];
  }
  out.cost = cost;
  out.used_points = used_points;
  out.skipped_points = points - used_points;
  return out;
}

RegistrationNormalEquations sum_of(const RegistrationNormalEquations& a,
                                   const RegistrationNormalEquations& b) {
  RegistrationNormalEquations sum;
  sum.hessian_i = a.hessian_i + b.hessian_i;
  sum.gradient_i = a.gradient_i + b.gradient_i;
  sum.cost = a.cost + b.cost;
  sum.used_points = a.used_points + b.used_points;
  sum.skipped_points = a.skipped_points + b.skipped_points;
  return sum;
}

bool registration_uses_tsdf_target(const RegistrationResidualConfig& config) {
  return config.distance == RegistrationDistance::kTsdfNearSurface && config.coarse_stride_vox <= 1;
}

// The kernels read the map; their views are non-const because kernels share one view type.
RegistrationDistanceLookup make_registration_lookup(const map::TsdfMap& map,
                                                    const RegistrationResidualConfig& config) {
  auto& mutable_map = const_cast<map::TsdfMap&>(map);
  RegistrationDistanceLookup lookup;
  lookup.esdf = integrators::EsdfLookup{
      map::BlockVoxelIndexer{map.blocks().device_view(), map.voxels_per_side()},
      mutable_map.esdf().view(), map.voxel_size_m()};
  lookup.tsdf = mutable_map.tsdf().view();
  lookup.tsdf_band_m = registration_uses_tsdf_target(config) ? config.tsdf_band_m : 0.0f;
  lookup.min_tsdf_weight = config.min_tsdf_weight;
  lookup.stride_vox = std::max<int32_t>(config.coarse_stride_vox, 1);
  return lookup;
}

RegistrationPoints extract_registration_points(const map::TsdfMap& map,
                                               const RegistrationPointsConfig& config,
                                               const Stream& stream) {
  if (!(config.sampling_ratio > 0.0f && config.sampling_ratio <= 1.0f)) {
    throw Error("extract_registration_points: sampling_ratio must be in (0, 1], got " +
                std::to_string(config.sampling_ratio));
  }
  if (!(config.surface_threshold_vox > 0.0f) || !std::isfinite(config.surface_threshold_vox)) {
    throw Error("extract_registration_points: surface_threshold_vox must be finite and > 0, got " +
                std::to_string(config.surface_threshold_vox));
  }
  RegistrationPoints result(map.device());
  // Blocks in ascending index order: the hash table's slot order differs between backends, and
  // the point order should not (parity tests, reproducible sampling of the solver's sums).
  Buffer<Index3D> indices(map.device());
  Buffer<uint32_t> slots(map.device());
  map.blocks().export_entries(&indices, &slots);
  std::vector<Index3D> host_indices = indices.to_host(stream);
  std::vector<uint32_t> host_slots = slots.to_host(stream);
  std::vector<size_t> order(host_indices.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return host_indices[a] < host_indices[b]; });
  std::vector<Index3D> sorted_indices(order.size());
  std::vector<uint32_t> sorted_slots(order.size());
  for (size_t k = 0; k < order.size(); ++k) {
    sorted_indices[k] = host_indices[order[k]];
    sorted_slots[k] = host_slots[order[k]];
  }
  auto device_indices = Buffer<Index3D>::from_host(map.device(), sorted_indices, stream);
  auto device_slots = Buffer<uint32_t>::from_host(map.device(), sorted_slots, stream);
  auto& mutable_map = const_cast<map::TsdfMap&>(map);
  result.surface_voxels = dispatch(map.device(), [&](auto backend) {
    return registration_collect_points(
        backend, mutable_map.tsdf().view(), device_indices.data(), device_slots.data(),
        static_cast<int64_t>(sorted_indices.size()), map.voxels_per_side(), map.voxel_size_m(),
        config, &result.points, stream);
  });
  return result;
}

void evaluate_registration_residuals(const RegistrationPoints& points_i, const map::TsdfMap& map_j,
                                     const Pose4Dof& T_W_Si, const Pose4Dof& T_W_Sj,
                                     const RegistrationResidualConfig& config,
                                     Buffer<RegistrationResidual>* residuals,
                                     const Stream& stream) {
  validate_registration_residual_config(config);
  check_finite_pose(T_W_Si, "T_W_Si");
  check_finite_pose(T_W_Sj, "T_W_Sj");
  check_same_device(points_i, map_j);
  if (residuals->device() != map_j.device()) {
    throw Error(
        "evaluate_registration_residuals: the residual buffer must live on submap j's device");
  }
  const int64_t count = static_cast<int64_t>(points_i.points.size());
  residuals->resize_discard(static_cast<size_t>(count));
  const RegistrationDistanceLookup lookup = make_registration_lookup(map_j, config);
  const RegistrationPairGeometry pair = registration_pair_geometry(T_W_Si, T_W_Sj);
  const RobustLossParams robust{config.loss, config.loss_scale};
  const bool tsdf_target = registration_uses_tsdf_target(config);
  dispatch(map_j.device(), [&](auto backend) {
    registration_evaluate(backend, points_i.points.data(), count, lookup, pair, robust, tsdf_target,
                          residuals->data(), stream);
  });
}

std::vector<RegistrationResidual> evaluate_registration_residuals(
    const RegistrationPoints& points_i, const map::TsdfMap& map_j, const Pose4Dof& T_W_Si,
    const Pose4Dof& T_W_Sj, const RegistrationResidualConfig& config) {
  const Stream stream(map_j.device());
  Buffer<RegistrationResidual> residuals(map_j.device());
  evaluate_registration_residuals(points_i, map_j, T_W_Si, T_W_Sj, config, &residuals, stream);
  return residuals.to_host(stream);
}

namespace {

RegistrationNormalEquations normal_equations_into(const RegistrationPoints& points_i,
                                                  const map::TsdfMap& map_j, const Pose4Dof& T_W_Si,
                                                  const Pose4Dof& T_W_Sj,
                                                  const RegistrationResidualConfig& config,
                                                  Buffer<RegistrationResidual>* scratch,
                                                  const Stream& stream) {
  evaluate_registration_residuals(points_i, map_j, T_W_Si, T_W_Sj, config, scratch, stream);
  const int64_t count = static_cast<int64_t>(scratch->size());
  const RegistrationSums sums = dispatch(map_j.device(), [&](auto backend) {
    return registration_reduce(backend, scratch->data(), count, stream);
  });
  return normal_equations_from_sums(sums.hessian, sums.gradient, sums.cost, sums.used, count);
}

}  // namespace

RegistrationNormalEquations registration_normal_equations(
    const RegistrationPoints& points_i, const map::TsdfMap& map_j, const Pose4Dof& T_W_Si,
    const Pose4Dof& T_W_Sj, const RegistrationResidualConfig& config, const Stream& stream) {
  Buffer<RegistrationResidual> scratch(map_j.device());
  return normal_equations_into(points_i, map_j, T_W_Si, T_W_Sj, config, &scratch, stream);
}

namespace {

void check_symmetric_pair(const SymmetricRegistrationPair& pair) {
  if (!pair.points_i || !pair.map_j || !pair.points_j || !pair.map_i) {
    throw Error("symmetric registration: points_i, map_j, points_j and map_i must all be given");
  }
  if (!(pair.reverse_weight_scale > 0.0 && std::isfinite(pair.reverse_weight_scale))) {
    throw Error("symmetric registration: reverse_weight_scale must be finite and > 0, got " +
                std::to_string(pair.reverse_weight_scale));
  }
}

// Submap j's points in submap i's field as sums over T_Sj_Si: the points' own pose is then
// T_Si_Sj = T_Sj_Si^-1 (submap i the reference), and the chain rule through the inverse turns
// their Jacobian into one with respect to T_Sj_Si.
RegistrationNormalEquations reverse_normal_equations(const SymmetricRegistrationPair& pair,
                                                     const Pose4Dof& T_Sj_Si,
                                                     const RegistrationResidualConfig& config,
                                                     Buffer<RegistrationResidual>* scratch,
                                                     const Stream& stream) {
  const double k = pair.reverse_weight_scale;
  RegistrationResidualConfig reverse_config = config;
  // The loss at scale a of residuals times sqrt(k) is k times the loss at scale a / sqrt(k).
  reverse_config.loss_scale = config.loss_scale / std::sqrt(k);
  const RegistrationNormalEquations of_inverse =
      normal_equations_into(*pair.points_j, *pair.map_i, inverse_pose_4dof(T_Sj_Si), Pose4Dof(),
                            reverse_config, scratch, stream);
  const Eigen::Matrix4d A = inverse_pose_4dof_jacobian(T_Sj_Si);
  RegistrationNormalEquations out = of_inverse;
  out.hessian_i = k * A.transpose() * of_inverse.hessian_i * A;
  out.gradient_i = k * A.transpose() * of_inverse.gradient_i;
  out.cost = k * of_inverse.cost;
  return out;
}

// One pair through the batched aligner (registration_batch.h), its failure thrown.
RegistrationResult align_one_pair(const RegistrationBatchPair& pair,
                                  const RegistrationAlignerConfig& config, const Stream& stream) {
  const RegistrationBatchOutcome outcome = align_submap_pairs({pair}, config, stream).front();
  if (outcome.status != RegistrationBatchOutcome::Status::kAligned) throw Error(outcome.failure);
  return outcome.result;
}

}  // namespace

RegistrationResult align_submaps(const RegistrationPoints& points_i, const map::TsdfMap& map_j,
                                 const Pose4Dof& initial_T_Sj_Si,
                                 const RegistrationAlignerConfig& config, const Stream& stream) {
  check_same_device(points_i, map_j);
  RegistrationBatchPair pair;
  pair.points_i = &points_i;
  pair.map_j = &map_j;
  pair.start_T_Sj_Si = initial_T_Sj_Si;
  return align_one_pair(pair, config, stream);
}

namespace {
// Both directions' sums at T_Sj_Si, in the caller's scratch (reused across LM iterations).
RegistrationNormalEquations two_way_sums(const SymmetricRegistrationPair& pair,
                                         const Pose4Dof& T_Sj_Si,
                                         const RegistrationResidualConfig& config,
                                         Buffer<RegistrationResidual>* scratch,
                                         Buffer<RegistrationResidual>* reverse_scratch,
                                         const Stream& stream) {
  return sum_of(normal_equations_into(*pair.points_i, *pair.map_j, T_Sj_Si, Pose4Dof(), config,
                                      scratch, stream),
                reverse_normal_equations(pair, T_Sj_Si, config, reverse_scratch, stream));
}
}  // namespace

RegistrationNormalEquations symmetric_registration_normal_equations(
    const SymmetricRegistrationPair& pair, const Pose4Dof& T_Sj_Si,
    const RegistrationResidualConfig& config, const Stream& stream) {
  check_symmetric_pair(pair);
  Buffer<RegistrationResidual> scratch(pair.map_j->device()), reverse_scratch(pair.map_i->device());
  return two_way_sums(pair, T_Sj_Si, config, &scratch, &reverse_scratch, stream);
}

RegistrationResult align_submaps_symmetric(const SymmetricRegistrationPair& pair,
                                           const Pose4Dof& initial_T_Sj_Si,
                                           const RegistrationAlignerConfig& config,
                                           const Stream& stream) {
  check_symmetric_pair(pair);
  RegistrationBatchPair batch_pair;
  batch_pair.points_i = pair.points_i;
  batch_pair.map_j = pair.map_j;
  batch_pair.points_j = pair.points_j;
  batch_pair.map_i = pair.map_i;
  batch_pair.reverse_weight_scale = pair.reverse_weight_scale;
  batch_pair.start_T_Sj_Si = initial_T_Sj_Si;
  return align_one_pair(batch_pair, config, stream);
}

Constraint4Dof make_registration_constraint(int32_t vertex_j, int32_t vertex_i,
                                            const RegistrationResult& result,
                                            double residual_sigma) {
  if (!(residual_sigma > 0.0 && std::isfinite(residual_sigma))) {
    throw Error("make_registration_constraint: residual_sigma must be finite and > 0, got " +
                std::to_string(residual_sigma));
  }
  // With T_W_Sj = identity the aligner's parameters are exactly the 4-DoF relative measurement
  // (dx, dy, dz in frame j, dyaw), and the relative residual's Jacobian with respect to the `to`
  // pose is the identity there: J^T J carries over as the information matrix.
  const Eigen::Matrix4d information = result.hessian / (residual_sigma * residual_sigma);
  return make_relative_constraint_4dof(vertex_j, vertex_i, result.T_Sj_Si, information);
}

SubmapFootprint submap_footprint(const map::TsdfMap& map) {
  SubmapFootprint footprint;
  footprint.block_size_m = map.block_size_m();
  const Stream stream(map.device());
  Buffer<Index3D> indices(map.device());
  Buffer<uint32_t> slots(map.device());
  map.blocks().export_entries(&indices, &slots);
  footprint.blocks = indices.to_host(stream);
  std::vector<uint64_t> keys;
  keys.reserve(footprint.blocks.size());
  for (const Index3D& b : footprint.blocks) keys.push_back(map::pack_block_key(b));
  footprint.keys = map::BlockKeySet(keys);
  if (footprint.blocks.empty()) return footprint;
  footprint.block_min = footprint.block_max = footprint.blocks.front();
  for (const Index3D& b : footprint.blocks) {
    footprint.block_min =
        Index3D(std::min(footprint.block_min.x, b.x), std::min(footprint.block_min.y, b.y),
                std::min(footprint.block_min.z, b.z));
    footprint.block_max =
        Index3D(std::max(footprint.block_max.x, b.x), std::max(footprint.block_max.y, b.y),
                std::max(footprint.block_max.z, b.z));
  }
  return footprint;
}

SubmapOverlap submap_overlap(const map::TsdfMap& map_i, const Pose4Dof& T_W_Si,
                             const map::TsdfMap& map_j, const Pose4Dof& T_W_Sj,
                             int64_t min_shared_blocks) {
  check_finite_pose(T_W_Si, "T_W_Si");
  check_finite_pose(T_W_Sj, "T_W_Sj");
  if (map_i.block_size_m() != map_j.block_size_m()) {
    throw Error("submap_overlap: the submaps have different block sizes (" +
                std::to_string(map_i.block_size_m()) + " and " +
                std::to_string(map_j.block_size_m()) + " m)");
  }
  return submap_overlap(submap_footprint(map_i), T_W_Si, submap_footprint(map_j), T_W_Sj,
                        min_shared_blocks);
}

namespace {

// The pose applied to p, its yaw's cosine and sine computed once by the caller for many points.
Eigen::Vector3d pose_4dof_apply(const Pose4Dof& pose, double c, double s,
                                const Eigen::Vector3d& p) {
  return Eigen::Vector3d(c * p.x() - s * p.y() + pose.x, s * p.x() + c * p.y() + pose.y,
                         p.z() + pose.z);
}

// The inverse: a world point in the pose's frame.
Eigen::Vector3d pose_4dof_unapply(const Pose4Dof& pose, double c, double s,
                                  const Eigen::Vector3d& w) {
  const Eigen::Vector3d d(w.x() - pose.x, w.y() - pose.y, w.z() - pose.z);
  return Eigen::Vector3d(c * d.x() + s * d.y(), -s * d.x() + c * d.y(), d.z());
}

// The 8 corners of a footprint's block-index box, in metres of its own frame.
std::array<Eigen::Vector3d, 8> footprint_corners(const SubmapFootprint& footprint) {
  const double block_m = footprint.block_size_m;
  const Eigen::Vector3d block_lo(footprint.block_min.x * block_m, footprint.block_min.y * block_m,
                                 footprint.block_min.z * block_m);
  const Eigen::Vector3d block_hi =
      Eigen::Vector3d(footprint.block_max.x * block_m, footprint.block_max.y * block_m,
                      footprint.block_max.z * block_m) +
      Eigen::Vector3d::Constant(block_m);
  std::array<Eigen::Vector3d, 8> corners;
  for (int c = 0; c < 8; ++c) {
    corners[c] = Eigen::Vector3d((c & 1) ? block_hi.x() : block_lo.x(),
                                 (c & 2) ? block_hi.y() : block_lo.y(),
                                 (c & 4) ? block_hi.z() : block_lo.z());
  }
  return corners;
}

// World AABB of a footprint: the 8 corners of its block-index box, transformed.
void footprint_world_box(const SubmapFootprint& footprint, const Pose4Dof& pose,
                         Eigen::Vector3d* lo, Eigen::Vector3d* hi) {
  *lo = Eigen::Vector3d::Constant(1e300);
  *hi = Eigen::Vector3d::Constant(-1e300);
  const double cos_yaw = std::cos(pose.yaw), sin_yaw = std::sin(pose.yaw);
  for (const Eigen::Vector3d& corner : footprint_corners(footprint)) {
    const Eigen::Vector3d w = pose_4dof_apply(pose, cos_yaw, sin_yaw, corner);
    *lo = lo->cwiseMin(w);
    *hi = hi->cwiseMax(w);
  }
}

// The box of `footprint_j`'s blocks (its frame j at T_W_Sj) seen from frame i at T_W_Si: the
// axis-aligned box in frame i of the eight corners, grown by `margin_m`. A point of frame i
// outside it is outside footprint j's block box, and so in none of its blocks.
void footprint_box_in_frame(const SubmapFootprint& footprint_j, const Pose4Dof& T_W_Sj,
                            const Pose4Dof& T_W_Si, double margin_m, Eigen::Vector3d* lo,
                            Eigen::Vector3d* hi) {
  const double c_j = std::cos(T_W_Sj.yaw), s_j = std::sin(T_W_Sj.yaw);
  const double c_i = std::cos(T_W_Si.yaw), s_i = std::sin(T_W_Si.yaw);
  *lo = Eigen::Vector3d::Constant(1e300);
  *hi = Eigen::Vector3d::Constant(-1e300);
  for (const Eigen::Vector3d& corner : footprint_corners(footprint_j)) {
    const Eigen::Vector3d in_i =
        pose_4dof_unapply(T_W_Si, c_i, s_i, pose_4dof_apply(T_W_Sj, c_j, s_j, corner));
    *lo = lo->cwiseMin(in_i);
    *hi = hi->cwiseMax(in_i);
  }
  *lo -= Eigen::Vector3d::Constant(margin_m);
  *hi += Eigen::Vector3d::Constant(margin_m);
}

}  // namespace

SubmapOverlap submap_overlap(const SubmapFootprint& footprint_i, const Pose4Dof& T_W_Si,
                             const SubmapFootprint& footprint_j, const Pose4Dof& T_W_Sj,
                             int64_t min_shared_blocks) {
  check_finite_pose(T_W_Si, "T_W_Si");
  check_finite_pose(T_W_Sj, "T_W_Sj");
  if (footprint_i.block_size_m != footprint_j.block_size_m) {
    throw Error("submap_overlap: the submaps have different block sizes (" +
                std::to_string(footprint_i.block_size_m) + " and " +
                std::to_string(footprint_j.block_size_m) + " m)");
  }
  SubmapOverlap overlap;
  if (footprint_i.blocks.empty() || footprint_j.blocks.empty()) return overlap;
  Eigen::Vector3d lo_i, hi_i, lo_j, hi_j;
  footprint_world_box(footprint_i, T_W_Si, &lo_i, &hi_i);
  footprint_world_box(footprint_j, T_W_Sj, &lo_j, &hi_j);
  overlap.bounding_boxes_intersect =
      (lo_i.array() <= hi_j.array()).all() && (lo_j.array() <= hi_i.array()).all();
  if (!overlap.bounding_boxes_intersect) return overlap;
  // Finer check: block centres of i, moved into frame j, landing in allocated blocks of j. A
  // centre outside j's block box seen from frame i is skipped before the move; the margin (a
  // hundredth of a block) keeps that test on the safe side of the move's rounding, so the count
  // is the same as without it.
  const double block_m = footprint_i.block_size_m;
  const double c = std::cos(T_W_Sj.yaw), s = std::sin(T_W_Sj.yaw);
  const double c_i = std::cos(T_W_Si.yaw), s_i = std::sin(T_W_Si.yaw);
  Eigen::Vector3d j_lo, j_hi;
  footprint_box_in_frame(footprint_j, T_W_Sj, T_W_Si, 0.01 * block_m, &j_lo, &j_hi);
  for (const Index3D& b : footprint_i.blocks) {
    const Eigen::Vector3d centre((b.x + 0.5) * block_m, (b.y + 0.5) * block_m,
                                 (b.z + 0.5) * block_m);
    if ((centre.array() < j_lo.array()).any() || (centre.array() > j_hi.array()).any()) continue;
    const Eigen::Vector3d in_j =
        pose_4dof_unapply(T_W_Sj, c, s, pose_4dof_apply(T_W_Si, c_i, s_i, centre));
    const Index3D block(static_cast<int32_t>(std::floor(in_j.x() / block_m)),
                        static_cast<int32_t>(std::floor(in_j.y() / block_m)),
                        static_cast<int32_t>(std::floor(in_j.z() / block_m)));
    const bool in_box = block.x >= footprint_j.block_min.x && block.x <= footprint_j.block_max.x &&
                        block.y >= footprint_j.block_min.y && block.y <= footprint_j.block_max.y &&
                        block.z >= footprint_j.block_min.z && block.z <= footprint_j.block_max.z;
    if (in_box && footprint_j.keys.contains(map::pack_block_key(block))) ++overlap.shared_blocks;
  }
  overlap.overlapping = overlap.shared_blocks >= std::max<int64_t>(min_shared_blocks, 1);
  return overlap;
}

}  // namespace backend
}  // namespace covox

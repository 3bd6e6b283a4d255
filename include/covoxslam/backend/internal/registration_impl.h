#pragma once
// Registration steps written once for both backends (instantiated in
// src/backend/registration_cpu.cpp and cuda/backend/registration_cuda.cu).
#include "covoxslam/backend/internal/registration_ops.h"
#include <thrust/functional.h>

#include "covoxslam/core/parallel.h"
#include "covoxslam/map/block_voxel_indexer.h"

namespace covox {
namespace backend {

template <class Backend>
int64_t registration_collect_points(Backend backend, VoxelView<map::TsdfVoxel, Layout::kSoA> tsdf,
                                    const Index3D* block_indices, const uint32_t* block_slots,
                                    int64_t block_count, int32_t side, float voxel_size_m,
                                    const RegistrationPointsConfig& config,
                                    Buffer<RegistrationPoint>* points, const Stream& stream) {
  const int64_t per_block = static_cast<int64_t>(side) * side * side;
  const int64_t total = block_count * per_block;
  if (total == 0) {
    points->resize_discard(0);
    return 0;
  }
  // flags: bit 0 surface voxel, bit 1 also sampled. Positions come from a scan of the sampled bit,
  // so the output keeps the block order the caller fixed: the same on both backends.
  Buffer<int64_t> surface(points->device(), static_cast<size_t>(total));
  Buffer<int64_t> offsets(points->device(), static_cast<size_t>(total));
  int64_t* surface_flags = surface.data();
  int64_t* sampled = offsets.data();
  const float threshold_m = config.surface_threshold_vox * voxel_size_m;
  const float min_weight = config.min_weight;
  const double ratio = config.sampling_ratio;
  const uint32_t seed = config.sampling_seed;
  parallel_for(backend, stream, total, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / per_block, k = i % per_block;
    const map::TsdfVoxel voxel = tsdf.load(static_cast<int64_t>(block_slots[b]) * per_block + k);
    const bool is_surface = voxel.weight >= min_weight && fabsf(voxel.distance_m) < threshold_m;
    surface_flags[i] = is_surface ? 1 : 0;
    if (!is_surface) {
      sampled[i] = 0;
      return;
    }
    const Index3D v = map::global_voxel(block_indices[b], k, side);
    sampled[i] = registration_sample_uniform(v.x, v.y, v.z, seed) < ratio ? 1 : 0;
  });
  const int64_t surface_count =
      reduce(backend, stream, surface_flags, total, int64_t(0), thrust::plus<int64_t>());
  const int64_t last_flag = offsets.element(static_cast<size_t>(total - 1), stream);
  exclusive_scan(backend, stream, sampled, total, sampled);
  const int64_t kept = offsets.element(static_cast<size_t>(total - 1), stream) + last_flag;
  points->resize_discard(static_cast<size_t>(kept));
  RegistrationPoint* out = points->data();
  // Scatter: element i is kept when its offset differs from the next one's (or, for the last,
  // when it was flagged).
  parallel_for(backend, stream, total, [=] COVOX_HD(int64_t i) {
    const int64_t next = i + 1 < total ? sampled[i + 1] : kept;
    if (next == sampled[i]) return;
    const int64_t b = i / per_block, k = i % per_block;
    const Index3D v = map::global_voxel(block_indices[b], k, side);
    const map::TsdfVoxel voxel = tsdf.load(static_cast<int64_t>(block_slots[b]) * per_block + k);
    RegistrationPoint p;
    p.position_m = Vec3f((v.x + 0.5f) * voxel_size_m, (v.y + 0.5f) * voxel_size_m,
                         (v.z + 0.5f) * voxel_size_m);
    p.tsdf_distance_m = voxel.distance_m;
    p.weight = voxel.weight;
    out[sampled[i]] = p;
  });
  stream.synchronize();
  return surface_count;
}

template <class Backend>
void registration_evaluate(Backend backend, const RegistrationPoint* points, int64_t count,
                           RegistrationDistanceLookup lookup, RegistrationPairGeometry pair,
                           RobustLossParams robust, bool tsdf_target, RegistrationResidual* out,
                           const Stream& stream) {
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    out[i] = registration_residual(points[i], lookup, pair, robust, tsdf_target);
  });
  stream.synchronize();
}

template <class Backend>
RegistrationSums registration_reduce(Backend backend, const RegistrationResidual* residuals,
                                     int64_t count, const Stream& stream) {
  return transform_reduce(backend, stream, residuals, count, RegistrationSumsOfResidual{},
                          RegistrationSums{}, AddRegistrationSums{});
}

#define COVOX_INSTANTIATE_REGISTRATION(Backend)                                                    \
  template int64_t registration_collect_points<Backend>(                                           \
      Backend, VoxelView<map::TsdfVoxel, Layout::kSoA>, const Index3D*, const uint32_t*, int64_t,  \
      int32_t, float, const RegistrationPointsConfig&, Buffer<RegistrationPoint>*, const Stream&); \
  template void registration_evaluate<Backend>(                                                    \
      Backend, const RegistrationPoint*, int64_t, RegistrationDistanceLookup,                      \
      RegistrationPairGeometry, RobustLossParams, bool, RegistrationResidual*, const Stream&);     \
  template RegistrationSums registration_reduce<Backend>(Backend, const RegistrationResidual*,     \
                                                         int64_t, const Stream&);

}  // namespace backend
}  // namespace covox

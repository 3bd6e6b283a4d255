#pragma once
// Definitions for voxel_pool_ops.h; included only by the two backend instantiation files.
#include "covoxslam/core/parallel.h"
#include "covoxslam/map/voxel_pool_ops.h"

namespace covox::map {

template <class Backend, class Voxel, Layout L>
void gather_voxel_distances(Backend backend, const Stream& stream, VoxelView<Voxel, L> voxels,
                            const uint32_t* voxel_indices, int64_t count, float* distances_out) {
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    distances_out[i] = voxels.template get<&Voxel::distance_m>(voxel_indices[i]);
  });
}

template <class Backend, class Voxel, Layout L>
void blend_tsdf_updates(Backend backend, const Stream& stream, VoxelView<Voxel, L> voxels,
                        const uint32_t* voxel_indices, const float* distances_m,
                        const float* weights, int64_t count, float max_weight) {
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    const uint32_t index = voxel_indices[i];
    float& distance = voxels.template get<&Voxel::distance_m>(index);
    float& weight = voxels.template get<&Voxel::weight>(index);
    const float update_weight = weights[i];
    const float combined_weight = weight + update_weight;
    if (combined_weight <= 0.0f) return;
    distance = (distance * weight + distances_m[i] * update_weight) / combined_weight;
    weight = combined_weight < max_weight ? combined_weight : max_weight;
  });
}

#define COVOX_INSTANTIATE_VOXEL_POOL_OPS_FOR(Backend, Voxel, L)                                    \
  template void gather_voxel_distances<Backend, Voxel, L>(                                         \
      Backend, const Stream&, VoxelView<Voxel, L>, const uint32_t*, int64_t, float*);              \
  template void blend_tsdf_updates<Backend, Voxel, L>(Backend, const Stream&, VoxelView<Voxel, L>, \
                                                      const uint32_t*, const float*, const float*, \
                                                      int64_t, float);

#define COVOX_INSTANTIATE_VOXEL_POOL_OPS(Backend)                               \
  COVOX_INSTANTIATE_VOXEL_POOL_OPS_FOR(Backend, TsdfVoxel, Layout::kSoA)        \
  COVOX_INSTANTIATE_VOXEL_POOL_OPS_FOR(Backend, TsdfVoxel, Layout::kAoS)        \
  COVOX_INSTANTIATE_VOXEL_POOL_OPS_FOR(Backend, ColoredTsdfVoxel, Layout::kSoA) \
  COVOX_INSTANTIATE_VOXEL_POOL_OPS_FOR(Backend, ColoredTsdfVoxel, Layout::kAoS)

}  // namespace covox::map

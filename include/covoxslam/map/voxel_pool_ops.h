#pragma once
// Operations on voxel pools that must behave the same for both layouts and both backends.
// Instantiated for TsdfVoxel and ColoredTsdfVoxel, SoA and AoS, CPU and CUDA.
#include <cstdint>

#include "covoxslam/core/device.h"
#include "covoxslam/core/soa_container.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/voxels.h"

namespace covox::map {

// distances_out[i] = distance_m of voxel voxel_indices[i]: reads one field only, which is where
// the SoA layout pays off.
template <class Backend, class Voxel, Layout L>
void gather_voxel_distances(Backend backend, const Stream& stream, VoxelView<Voxel, L> voxels,
                            const uint32_t* voxel_indices, int64_t count, float* distances_out);

// The last step of TSDF fusion: for each *distinct* voxel index, blends one merged update
// (signed distance, weight) into the stored voxel with a weighted average, capping the weight
// at max_weight. Indices must be unique, so no two threads write the same voxel (no atomics).
template <class Backend, class Voxel, Layout L>
void blend_tsdf_updates(Backend backend, const Stream& stream, VoxelView<Voxel, L> voxels,
                        const uint32_t* voxel_indices, const float* distances_m,
                        const float* weights, int64_t count, float max_weight);

}  // namespace covox::map

#pragma once
// The ESDF queries' column keys and backend-templated steps (defined in esdf_queries_impl.h,
// instantiated per backend) over the device-side lookup of esdf_lookup.h.
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/soa_container.h"
#include "covoxslam/integrators/esdf_lookup.h"
#include "covoxslam/integrators/esdf_queries.h"
#include "covoxslam/map/block_voxel_indexer.h"
#include "covoxslam/map/voxels.h"

namespace covox::integrators {

// (x, y) voxel column as a sortable key. The bias keeps every real column away from the
// all-ones "unused" key (x = y = -1 would hit it without one).
constexpr int64_t kColumnBias = int64_t(1) << 30;
COVOX_HD_INLINE uint64_t esdf_column_key(int32_t x, int32_t y) {
  return (static_cast<uint64_t>(x + kColumnBias) << 32) | static_cast<uint64_t>(y + kColumnBias);
}
inline void esdf_column_of_key(uint64_t key, int32_t* x, int32_t* y) {
  *x = static_cast<int32_t>(static_cast<int64_t>(key >> 32) - kColumnBias);
  *y = static_cast<int32_t>(static_cast<int64_t>(key & 0xffffffffu) - kColumnBias);
}

template <class Backend>
void esdf_query_points(Backend backend, EsdfLookup lookup, const Vec3f* points, int64_t count,
                       EsdfSample* out, const Stream& stream);

template <class Backend>
int64_t esdf_collect_layer(Backend backend, VoxelView<map::EsdfVoxel, Layout::kSoA> esdf,
                           const Index3D* block_indices, const uint32_t* block_slots,
                           int64_t block_count, int32_t side, int32_t layer_min, int32_t layer_max,
                           Buffer<uint64_t>* column_keys, Buffer<float>* distances,
                           const Stream& stream);

template <class Backend>
void esdf_flag_band(Backend backend, VoxelView<map::EsdfVoxel, Layout::kSoA> esdf,
                    const uint32_t* block_slots, int64_t block_count, int32_t side,
                    float max_distance_m, uint32_t* flags, const Stream& stream);

template <class Backend>
void esdf_gather_band(Backend backend, VoxelView<map::EsdfVoxel, Layout::kSoA> esdf,
                      const Index3D* block_indices, const uint32_t* block_slots,
                      int64_t block_count, int32_t side, float voxel_size_m, const uint32_t* flags,
                      const uint32_t* offsets, Vec3f* positions_m, float* distances_m,
                      const Stream& stream);

}  // namespace covox::integrators

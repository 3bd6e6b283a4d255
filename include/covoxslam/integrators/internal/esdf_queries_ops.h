#pragma once
// The device-side ESDF lookup and the backend-templated query steps (defined in
// esdf_queries_impl.h, instantiated per backend).
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/soa_container.h"
#include "covoxslam/integrators/esdf_queries.h"
#include "covoxslam/map/block_voxel_indexer.h"
#include "covoxslam/map/voxels.h"

namespace covox::integrators {

// What a kernel needs to look a voxel up by its global index.
struct EsdfLookup {
  map::BlockVoxelIndexer indexer;
  VoxelView<map::EsdfVoxel, Layout::kSoA> esdf;
  float voxel_size;

  // Returns false for unallocated or unobserved voxels.
  COVOX_HD_INLINE bool voxel(const Index3D& v, float* distance) const {
    const int64_t index = indexer.pool_index(v);
    if (index < 0 || !esdf.get<&map::EsdfVoxel::observed>(index)) return false;
    *distance = esdf.get<&map::EsdfVoxel::distance_m>(index);
    return true;
  }

  COVOX_HD_INLINE EsdfSample sample(const Vec3f& p) const {
    EsdfSample out;
    // Voxel centres sit at (i + 0.5) * voxel_size: interpolate between the 8 around p.
    const float gx = p.x / voxel_size - 0.5f, gy = p.y / voxel_size - 0.5f,
                gz = p.z / voxel_size - 0.5f;
    const Index3D base(static_cast<int32_t>(floorf(gx)), static_cast<int32_t>(floorf(gy)),
                       static_cast<int32_t>(floorf(gz)));
    const float fx = gx - base.x, fy = gy - base.y, fz = gz - base.z;
    float d[8];
    for (int c = 0; c < 8; ++c) {
      if (!voxel(base + Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1), &d[c])) return out;
    }
    const float x00 = d[0] + fx * (d[1] - d[0]), x10 = d[2] + fx * (d[3] - d[2]);
    const float x01 = d[4] + fx * (d[5] - d[4]), x11 = d[6] + fx * (d[7] - d[6]);
    const float y0 = x00 + fy * (x10 - x00), y1 = x01 + fy * (x11 - x01);
    out.distance_m = y0 + fz * (y1 - y0);
    // Derivatives of the trilinear form, divided by the voxel size for metres.
    const float ddx = (1 - fz) * ((1 - fy) * (d[1] - d[0]) + fy * (d[3] - d[2])) +
                      fz * ((1 - fy) * (d[5] - d[4]) + fy * (d[7] - d[6]));
    const float ddy = (1 - fz) * (x10 - x00) + fz * (x11 - x01);
    const float ddz = y1 - y0;
    out.gradient = Vec3f(ddx / voxel_size, ddy / voxel_size, ddz / voxel_size);
    out.valid = 1;
    return out;
  }
};

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

#pragma once
// ESDF queries and slices, written once for both backends.
#include <thrust/functional.h>

#include "covoxslam/core/parallel.h"
#include "covoxslam/integrators/internal/esdf_queries_ops.h"
#include "covoxslam/map/block_voxel_indexer.h"

namespace covox::integrators {

template <class Backend>
void esdf_query_points(Backend backend, EsdfLookup lookup, const Vec3f* points, int64_t count,
                       EsdfSample* out, const Stream& stream) {
  parallel_for(backend, stream, count,
               [=] COVOX_HD(int64_t i) { out[i] = lookup.sample(points[i]); });
  stream.synchronize();
}

// Per voxel of every block: a slice point if the voxel is observed and its layer is in
// [layer_min, layer_max]; the (x, y) column key for squashing.
template <class Backend>
int64_t esdf_collect_layer(Backend backend, VoxelView<map::EsdfVoxel, Layout::kSoA> esdf,
                           const Index3D* block_indices, const uint32_t* block_slots,
                           int64_t block_count, int32_t side, int32_t layer_min, int32_t layer_max,
                           Buffer<uint64_t>* column_keys, Buffer<float>* distances,
                           const Stream& stream) {
  const int64_t per_block = static_cast<int64_t>(side) * side * side;
  const int64_t total = block_count * per_block;
  column_keys->resize_discard(total);
  distances->resize_discard(total);
  uint64_t* keys = column_keys->data();
  float* values = distances->data();
  parallel_for(backend, stream, total, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / per_block, k = i % per_block;
    const Index3D v = map::global_voxel(block_indices[b], k, side);
    const int64_t index = static_cast<int64_t>(block_slots[b]) * per_block + k;
    keys[i] = ~uint64_t(0);
    if (v.z < layer_min || v.z > layer_max || !esdf.get<&map::EsdfVoxel::observed>(index)) return;
    keys[i] = esdf_column_key(v.x, v.y);
    values[i] = esdf.get<&map::EsdfVoxel::distance_m>(index);
  });
  // Group by column, take the minimum distance of each; unused entries sort last.
  sort_by_key(backend, stream, keys, values, total);
  Buffer<uint64_t> unique_keys(column_keys->device(), total);
  Buffer<float> minima(column_keys->device(), total);
  const int64_t runs = reduce_by_key(backend, stream, keys, values, total, unique_keys.data(),
                                     minima.data(), thrust::minimum<float>());
  *column_keys = std::move(unique_keys);
  *distances = std::move(minima);
  const bool has_unused = runs > 0 && column_keys->element(runs - 1, stream) == ~uint64_t(0);
  return runs - (has_unused ? 1 : 0);
}

// Per voxel of every block: 1 when it is observed and its distance is at most max_distance_m,
// else 0 (the flags a scan turns into output positions).
template <class Backend>
void esdf_flag_band(Backend backend, VoxelView<map::EsdfVoxel, Layout::kSoA> esdf,
                    const uint32_t* block_slots, int64_t block_count, int32_t side,
                    float max_distance_m, uint32_t* flags, const Stream& stream) {
  const int64_t per_block = static_cast<int64_t>(side) * side * side;
  parallel_for(backend, stream, block_count * per_block, [=] COVOX_HD(int64_t i) {
    const int64_t index =
        static_cast<int64_t>(block_slots[i / per_block]) * per_block + i % per_block;
    flags[i] = esdf.get<&map::EsdfVoxel::observed>(index) &&
                       esdf.get<&map::EsdfVoxel::distance_m>(index) <= max_distance_m
                   ? 1u
                   : 0u;
  });
}

// Writes each flagged voxel's centre (metres, map frame) and distance at its scanned offset.
template <class Backend>
void esdf_gather_band(Backend backend, VoxelView<map::EsdfVoxel, Layout::kSoA> esdf,
                      const Index3D* block_indices, const uint32_t* block_slots,
                      int64_t block_count, int32_t side, float voxel_size_m, const uint32_t* flags,
                      const uint32_t* offsets, Vec3f* positions_m, float* distances_m,
                      const Stream& stream) {
  const int64_t per_block = static_cast<int64_t>(side) * side * side;
  parallel_for(backend, stream, block_count * per_block, [=] COVOX_HD(int64_t i) {
    if (!flags[i]) return;
    const int64_t b = i / per_block, k = i % per_block;
    const Index3D v = map::global_voxel(block_indices[b], k, side);
    const int64_t index = static_cast<int64_t>(block_slots[b]) * per_block + k;
    positions_m[offsets[i]] = Vec3f((v.x + 0.5f) * voxel_size_m, (v.y + 0.5f) * voxel_size_m,
                                    (v.z + 0.5f) * voxel_size_m);
    distances_m[offsets[i]] = esdf.get<&map::EsdfVoxel::distance_m>(index);
  });
  stream.synchronize();
}

#define COVOX_INSTANTIATE_ESDF_QUERIES(Backend)                                                   \
  template void esdf_query_points<Backend>(Backend, EsdfLookup, const Vec3f*, int64_t,            \
                                           EsdfSample*, const Stream&);                           \
  template int64_t esdf_collect_layer<Backend>(                                                   \
      Backend, VoxelView<map::EsdfVoxel, Layout::kSoA>, const Index3D*, const uint32_t*, int64_t, \
      int32_t, int32_t, int32_t, Buffer<uint64_t>*, Buffer<float>*, const Stream&);               \
  template void esdf_flag_band<Backend>(Backend, VoxelView<map::EsdfVoxel, Layout::kSoA>,         \
                                        const uint32_t*, int64_t, int32_t, float, uint32_t*,      \
                                        const Stream&);                                           \
  template void esdf_gather_band<Backend>(                                                        \
      Backend, VoxelView<map::EsdfVoxel, Layout::kSoA>, const Index3D*, const uint32_t*, int64_t, \
      int32_t, float, const uint32_t*, const uint32_t*, Vec3f*, float*, const Stream&);

}  // namespace covox::integrators

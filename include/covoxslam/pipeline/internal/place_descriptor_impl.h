#pragma once
// The surface columns of a submap for its place descriptor, written once for both backends.
//
// One thread per (block, column of the block): it walks the block's voxels of that (x, y) column
// and keeps the highest and lowest voxel layer (global z index) that holds a surface voxel
// (weight > 0 and |distance| below the band). The block columns are then sorted by their global
// (x, y) key and merged into one entry per map column (highest top, lowest bottom). Integer
// indices only: both backends give the same columns, bit for bit.
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/map/block_voxel_indexer.h"
#include "covoxslam/map/voxels.h"

namespace covox {
namespace pipeline {

// Key of a global voxel column; the signs are flipped so that the key order is the (x, y) order
// and no real column (|x|, |y| < 2^31 - 1) gets the unused key ~0.
COVOX_HD_INLINE uint64_t place_column_key(int32_t x, int32_t y) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(x) ^ 0x80000000u) << 32) |
         static_cast<uint64_t>(static_cast<uint32_t>(y) ^ 0x80000000u);
}
inline void place_column_of_key(uint64_t key, int32_t* x, int32_t* y) {
  *x = static_cast<int32_t>(static_cast<uint32_t>(key >> 32) ^ 0x80000000u);
  *y = static_cast<int32_t>(static_cast<uint32_t>(key & 0xffffffffu) ^ 0x80000000u);
}

// A column's span: its top layer in the high word and the complement of its bottom layer in the
// low word (both biased to unsigned), so the elementwise maximum merges two spans.
COVOX_HD_INLINE uint64_t place_pack_span(int32_t top, int32_t bottom) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(top) ^ 0x80000000u) << 32) |
         static_cast<uint64_t>(~(static_cast<uint32_t>(bottom) ^ 0x80000000u));
}
inline void place_unpack_span(uint64_t span, int32_t* top, int32_t* bottom) {
  *top = static_cast<int32_t>(static_cast<uint32_t>(span >> 32) ^ 0x80000000u);
  *bottom = static_cast<int32_t>(~static_cast<uint32_t>(span & 0xffffffffu) ^ 0x80000000u);
}

struct PlaceSpanMerge {
  COVOX_HD_INLINE uint64_t operator()(uint64_t a, uint64_t b) const {
    const uint64_t high = (a >> 32) > (b >> 32) ? (a >> 32) : (b >> 32);
    const uint64_t low =
        (a & 0xffffffffu) > (b & 0xffffffffu) ? (a & 0xffffffffu) : (b & 0xffffffffu);
    return (high << 32) | low;
  }
};

// Fills `keys` and `spans` with one entry per map column that holds a surface voxel, in key
// order; returns their number.
template <class Backend>
int64_t place_surface_columns(Backend backend, VoxelView<TsdfVoxel, Layout::kSoA> tsdf,
                              const Index3D* block_indices, const uint32_t* block_slots,
                              int64_t block_count, int32_t side, float surface_band_m,
                              Buffer<uint64_t>* keys, Buffer<uint64_t>* spans,
                              const Stream& stream) {
  const int64_t per_block = static_cast<int64_t>(side) * side;
  const int64_t total = block_count * per_block;
  if (total == 0) return 0;
  Buffer<uint64_t> column_keys(keys->device(), static_cast<size_t>(total));
  Buffer<uint64_t> column_spans(keys->device(), static_cast<size_t>(total));
  uint64_t* out_keys = column_keys.data();
  uint64_t* out_spans = column_spans.data();
  parallel_for(backend, stream, total, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / per_block, column = i % per_block;
    const Index3D block = block_indices[b];
    const int64_t base = static_cast<int64_t>(block_slots[b]) * per_block * side + column;
    int32_t top = 0, bottom = 0;
    bool any = false;
    for (int32_t z = 0; z < side; ++z) {
      const int64_t index = base + static_cast<int64_t>(z) * per_block;
      const float weight = tsdf.template get<&TsdfVoxel::weight>(index);
      const float distance = tsdf.template get<&TsdfVoxel::distance_m>(index);
      if (!(weight > 0.0f) || !(distance < surface_band_m && distance > -surface_band_m)) continue;
      const int32_t layer = block.z * side + z;
      if (!any) bottom = layer;
      top = layer;
      any = true;
    }
    out_keys[i] = ~uint64_t(0);
    if (!any) return;
    const int32_t x = block.x * side + static_cast<int32_t>(column % side);
    const int32_t y = block.y * side + static_cast<int32_t>(column / side);
    out_keys[i] = place_column_key(x, y);
    out_spans[i] = place_pack_span(top, bottom);
  });
  // Merge the block columns of each map column; unused entries sort last.
  sort_by_key(backend, stream, out_keys, out_spans, total);
  keys->resize_discard(static_cast<size_t>(total));
  spans->resize_discard(static_cast<size_t>(total));
  const int64_t runs = reduce_by_key(backend, stream, out_keys, out_spans, total, keys->data(),
                                     spans->data(), PlaceSpanMerge());
  const bool has_unused = runs > 0 && keys->element(runs - 1, stream) == ~uint64_t(0);
  return runs - (has_unused ? 1 : 0);
}

#define COVOX_INSTANTIATE_PLACE_DESCRIPTOR(Backend)                                          \
  template int64_t place_surface_columns<Backend>(                                           \
      Backend, VoxelView<TsdfVoxel, Layout::kSoA>, const Index3D*, const uint32_t*, int64_t, \
      int32_t, float, Buffer<uint64_t>*, Buffer<uint64_t>*, const Stream&);

}  // namespace pipeline
}  // namespace covox

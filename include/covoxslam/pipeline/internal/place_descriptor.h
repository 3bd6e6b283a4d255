#pragma once
// The surface columns of a submap for its place descriptor: the declaration and the column key
// helpers (the kernel is in place_descriptor_impl.h, instantiated for each backend).
//
// One thread per (block, column of the block): it walks the block's voxels of that (x, y) column
// and keeps the highest and lowest voxel layer (global z index) that holds a surface voxel
// (weight > 0 and |distance| below the band). The block columns are then sorted by their global
// (x, y) key and merged into one entry per map column (highest top, lowest bottom). Integer
// indices only: both backends give the same columns, bit for bit.
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/stream.h"
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

// Fills `keys` and `spans` with one entry per map column that holds a surface voxel, in key
// order; returns their number.
template <class Backend>
int64_t place_surface_columns(Backend backend, VoxelView<map::TsdfVoxel, Layout::kSoA> tsdf,
                              const Index3D* block_indices, const uint32_t* block_slots,
                              int64_t block_count, int32_t side, float surface_band_m,
                              Buffer<uint64_t>* keys, Buffer<uint64_t>* spans,
                              const Stream& stream);

}  // namespace pipeline
}  // namespace covox

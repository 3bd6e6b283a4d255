#pragma once
// The surface columns kernel of the place descriptor (declared in place_descriptor.h), written
// once for both backends: instantiated in src/pipeline/place_descriptor_cpu.cpp and
// cuda/pipeline/place_descriptor_cuda.cu.
#include "covoxslam/core/parallel.h"
#include "covoxslam/pipeline/internal/place_descriptor.h"

namespace covox {
namespace pipeline {

struct PlaceSpanMerge {
  COVOX_HD_INLINE uint64_t operator()(uint64_t a, uint64_t b) const {
    const uint64_t high = (a >> 32) > (b >> 32) ? (a >> 32) : (b >> 32);
    const uint64_t low =
        (a & 0xffffffffu) > (b & 0xffffffffu) ? (a & 0xffffffffu) : (b & 0xffffffffu);
    return (high << 32) | low;
  }
};

// One (block, column of the block): the highest and lowest layer of that column holding a surface
// voxel, as a column key and a packed span; ~0 as the key when the column holds none.
struct PlaceColumnSpan {
  VoxelView<map::TsdfVoxel, Layout::kSoA> tsdf;
  const Index3D* block_indices;
  const uint32_t* block_slots;
  int32_t side;
  float surface_band_m;
  uint64_t* out_keys;
  uint64_t* out_spans;

  COVOX_HD void operator()(int64_t i) const {
    const int64_t per_block = static_cast<int64_t>(side) * side;
    const int64_t b = i / per_block, column = i % per_block;
    const Index3D block = block_indices[b];
    const int64_t base = static_cast<int64_t>(block_slots[b]) * per_block * side + column;
    int32_t top = 0, bottom = 0;
    bool any = false;
    for (int32_t z = 0; z < side; ++z) {
      const int64_t index = base + static_cast<int64_t>(z) * per_block;
      const float weight = tsdf.template get<&map::TsdfVoxel::weight>(index);
      const float distance = tsdf.template get<&map::TsdfVoxel::distance_m>(index);
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
  }
};

template <class Backend>
int64_t place_surface_columns(Backend backend, VoxelView<map::TsdfVoxel, Layout::kSoA> tsdf,
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
  parallel_for(
      backend, stream, total,
      PlaceColumnSpan{tsdf, block_indices, block_slots, side, surface_band_m, out_keys, out_spans});
  // Merge the block columns of each map column; unused entries sort last.
  sort_by_key(backend, stream, out_keys, out_spans, total);
  keys->resize_discard(static_cast<size_t>(total));
  spans->resize_discard(static_cast<size_t>(total));
  const int64_t runs = reduce_by_key(backend, stream, out_keys, out_spans, total, keys->data(),
                                     spans->data(), PlaceSpanMerge());
  const bool has_unused = runs > 0 && keys->element(runs - 1, stream) == ~uint64_t(0);
  return runs - (has_unused ? 1 : 0);
}

#define COVOX_INSTANTIATE_PLACE_DESCRIPTOR(Backend)                                               \
  template int64_t place_surface_columns<Backend>(                                                \
      Backend, VoxelView<map::TsdfVoxel, Layout::kSoA>, const Index3D*, const uint32_t*, int64_t, \
      int32_t, float, Buffer<uint64_t>*, Buffer<uint64_t>*, const Stream&);

}  // namespace pipeline
}  // namespace covox

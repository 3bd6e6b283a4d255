#pragma once
// Definitions for submap_codec_kernels.h; included only by the two backend instantiation files.
#include "covoxslam/core/parallel.h"
#include "covoxslam/io/internal/submap_codec_kernels.h"
#include "covoxslam/io/internal/voxel_quantisation.h"

namespace covox::io::internal {

constexpr int kWordBits = 32;
constexpr int64_t kRecordIndexBytes = 12;                      // three int32
constexpr int64_t kRecordHeaderBytes = kRecordIndexBytes + 1;  // and the flags byte

// The byte offsets of one record's arrays (submap_codec.h's layout).
struct RecordFields {
  int64_t mask, distances, weights, rgb, color_weights;
  COVOX_HD_INLINE RecordFields(int64_t record, int32_t voxels_per_block, uint32_t observed) {
    const int64_t n = observed;
    mask = record + kRecordHeaderBytes;
    distances = mask + voxels_per_block / 8;
    weights = distances + 2 * n;
    rgb = weights + 2 * n;
    color_weights = rgb + 3 * n;
  }
};

COVOX_HD_INLINE void store_i32(uint8_t* at, int32_t value) {
  const uint32_t bits = static_cast<uint32_t>(value);
  for (int k = 0; k < 4; ++k) at[k] = static_cast<uint8_t>((bits >> (8 * k)) & 0xffu);
}

template <class Backend>
void quantised_word_masks(Backend backend, const Stream& stream, TsdfView tsdf, ColorView color,
                          const uint32_t* slots, int64_t blocks, int32_t voxels_per_block,
                          double distance_scale_m, uint32_t* masks, uint8_t* word_colors) {
  const int32_t words = voxels_per_block / kWordBits;
  parallel_for(backend, stream, blocks * words, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / words, w = i % words;
    const int64_t first = static_cast<int64_t>(slots[b]) * voxels_per_block + w * kWordBits;
    uint32_t bits = 0;
    uint8_t any_color = 0;
    for (int j = 0; j < kWordBits; ++j) {
      const QuantisedVoxel q =
          quantise(tsdf.load(first + j), color.load(first + j), distance_scale_m);
      if (!q.observed()) continue;
      bits |= 1u << j;
      any_color |= q.has_color() ? 1 : 0;
    }
    masks[i] = bits;
    word_colors[i] = any_color;
  });
}

template <class Backend>
void block_word_ranks(Backend backend, const Stream& stream, const uint32_t* masks,
                      const uint8_t* word_colors, int64_t blocks, int32_t words_per_block,
                      uint32_t* word_ranks, EncodedBlock* layout) {
  parallel_for(backend, stream, blocks, [=] COVOX_HD(int64_t b) {
    uint32_t rank = 0;
    uint32_t any_color = 0;
    for (int64_t w = b * words_per_block; w < (b + 1) * words_per_block; ++w) {
      word_ranks[w] = rank;
      rank += count_bits(masks[w]);
      if (word_colors) any_color |= word_colors[w];
    }
    layout[b].observed = rank;
    if (word_colors) layout[b].color = any_color;
  });
}

template <class Backend>
void write_block_records(Backend backend, const Stream& stream, TsdfView tsdf, ColorView color,
                         const uint32_t* slots, const Index3D* indices, const EncodedBlock* layout,
                         const uint32_t* masks, const uint32_t* word_ranks, int64_t blocks,
                         int32_t voxels_per_block, double distance_scale_m, uint8_t* bytes) {
  const int32_t words = voxels_per_block / kWordBits;
  parallel_for(backend, stream, blocks * words, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / words, w = i % words;
    const EncodedBlock block = layout[b];
    if (block.observed == 0) return;  // dropped: no record
    const RecordFields at(static_cast<int64_t>(block.record_offset), voxels_per_block,
                          block.observed);
    if (w == 0) {
      uint8_t* record = bytes + block.record_offset;
      store_i32(record, indices[b].x);
      store_i32(record + 4, indices[b].y);
      store_i32(record + 8, indices[b].z);
      record[kRecordIndexBytes] = static_cast<uint8_t>(block.color ? 1 : 0);
    }
    const uint32_t bits = masks[i];
    store_i32(bytes + at.mask + 4 * w, static_cast<int32_t>(bits));
    const int64_t first = static_cast<int64_t>(slots[b]) * voxels_per_block + w * kWordBits;
    for (int j = 0; j < kWordBits; ++j) {
      if (((bits >> j) & 1u) == 0) continue;
      const int64_t rank = word_ranks[i] + count_bits(bits & ((1u << j) - 1u));
      const QuantisedVoxel q =
          quantise(tsdf.load(first + j), color.load(first + j), distance_scale_m);
      store_u16(bytes + at.distances + 2 * rank, static_cast<uint16_t>(q.distance));
      store_u16(bytes + at.weights + 2 * rank, q.weight);
      if (!block.color) continue;
      bytes[at.rgb + 3 * rank] = q.r;
      bytes[at.rgb + 3 * rank + 1] = q.g;
      bytes[at.rgb + 3 * rank + 2] = q.b;
      store_u16(bytes + at.color_weights + 2 * rank, q.color_weight);
    }
  });
}

template <class Backend>
void read_word_masks(Backend backend, const Stream& stream, const uint8_t* bytes,
                     const EncodedBlock* layout, int64_t blocks, int32_t voxels_per_block,
                     uint32_t* masks) {
  const int32_t words = voxels_per_block / kWordBits;
  parallel_for(backend, stream, blocks * words, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / words, w = i % words;
    const uint8_t* mask = bytes + layout[b].record_offset + kRecordHeaderBytes + 4 * w;
    masks[i] = static_cast<uint32_t>(mask[0]) | (static_cast<uint32_t>(mask[1]) << 8) |
               (static_cast<uint32_t>(mask[2]) << 16) | (static_cast<uint32_t>(mask[3]) << 24);
  });
}

template <class Backend>
void read_block_voxels(Backend backend, const Stream& stream, const uint8_t* bytes,
                       const EncodedBlock* layout, const uint32_t* masks,
                       const uint32_t* word_ranks, int64_t blocks, int32_t voxels_per_block,
                       float distance_scale_m, TsdfView tsdf, ColorView color) {
  const int32_t words = voxels_per_block / kWordBits;
  parallel_for(backend, stream, blocks * words, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / words, w = i % words;
    const EncodedBlock block = layout[b];
    const RecordFields at(static_cast<int64_t>(block.record_offset), voxels_per_block,
                          block.observed);
    const uint32_t bits = masks[i];
    const int64_t first = b * voxels_per_block + w * kWordBits;
    for (int j = 0; j < kWordBits; ++j) {
      if (((bits >> j) & 1u) == 0) continue;
      const int64_t rank = word_ranks[i] + count_bits(bits & ((1u << j) - 1u));
      map::TsdfVoxel voxel;
      voxel.distance_m = dequantise_distance(
          static_cast<int16_t>(load_u16(bytes + at.distances + 2 * rank)), distance_scale_m);
      voxel.weight = half_bits_to_float(load_u16(bytes + at.weights + 2 * rank));
      tsdf.store(first + j, voxel);
      if (!block.color) continue;
      map::ColorVoxel colored;
      colored.r = bytes[at.rgb + 3 * rank];
      colored.g = bytes[at.rgb + 3 * rank + 1];
      colored.b = bytes[at.rgb + 3 * rank + 2];
      colored.weight = half_bits_to_float(load_u16(bytes + at.color_weights + 2 * rank));
      color.store(first + j, colored);
    }
  });
}

#define COVOX_INSTANTIATE_SUBMAP_CODEC_KERNELS(Backend)                                            \
  template void quantised_word_masks<Backend>(Backend, const Stream&, TsdfView, ColorView,         \
                                              const uint32_t*, int64_t, int32_t, double,           \
                                              uint32_t*, uint8_t*);                                \
  template void block_word_ranks<Backend>(Backend, const Stream&, const uint32_t*, const uint8_t*, \
                                          int64_t, int32_t, uint32_t*, EncodedBlock*);             \
  template void write_block_records<Backend>(                                                      \
      Backend, const Stream&, TsdfView, ColorView, const uint32_t*, const Index3D*,                \
      const EncodedBlock*, const uint32_t*, const uint32_t*, int64_t, int32_t, double, uint8_t*);  \
  template void read_word_masks<Backend>(Backend, const Stream&, const uint8_t*,                   \
                                         const EncodedBlock*, int64_t, int32_t, uint32_t*);        \
  template void read_block_voxels<Backend>(Backend, const Stream&, const uint8_t*,                 \
                                           const EncodedBlock*, const uint32_t*, const uint32_t*,  \
                                           int64_t, int32_t, float, TsdfView, ColorView);

}  // namespace covox::io::internal

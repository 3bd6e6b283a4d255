#pragma once
// The submap codec's steps on the map's own device (submap_codec.h's layout): a map is encoded
// and decoded where its voxels are, so only the compact bytes cross to the host. Defined in
// submap_codec_kernels_impl.h, instantiated per backend.
//
// Blocks are handled in the order they are stored (increasing index); a block's voxels come as
// mask words of 32 voxels, voxel k of a block in word k / 32, bit k % 32 (byte k / 8, bit k % 8 of
// the little-endian mask). A set voxel's place among its block's stored voxels (its rank) is the
// bits set before it: the word's rank (the bits of the words before) plus those below its bit.
#include <cstdint>

#include "covoxslam/core/soa_container.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/io/internal/submap_codec_layout.h"
#include "covoxslam/map/voxels.h"

namespace covox::io::internal {

using TsdfView = VoxelView<map::TsdfVoxel, Layout::kSoA>;
using ColorView = VoxelView<map::ColorVoxel, Layout::kSoA>;

// Encoding, step 1: per mask word of every block, the observed voxels' bits and whether any of
// them has colour. Block b's voxels start at slots[b] * voxels_per_block in the pools.
template <class Backend>
void quantised_word_masks(Backend backend, const Stream& stream, TsdfView tsdf, ColorView color,
                          const uint32_t* slots, int64_t blocks, int32_t voxels_per_block,
                          double distance_scale_m, uint32_t* masks, uint8_t* word_colors);

// Per block: each word's rank, the block's observed voxels and (with word_colors) its colour
// flag. word_colors may be null (decoding: the flag is read from the record).
template <class Backend>
void block_word_ranks(Backend backend, const Stream& stream, const uint32_t* masks,
                      const uint8_t* word_colors, int64_t blocks, int32_t words_per_block,
                      uint32_t* word_ranks, EncodedBlock* layout);

// Encoding, step 3: every non-empty block's record (index, flags, mask, fields) written at
// layout[b].record_offset of `bytes`; indices[b] the block index.
template <class Backend>
void write_block_records(Backend backend, const Stream& stream, TsdfView tsdf, ColorView color,
                         const uint32_t* slots, const Index3D* indices, const EncodedBlock* layout,
                         const uint32_t* masks, const uint32_t* word_ranks, int64_t blocks,
                         int32_t voxels_per_block, double distance_scale_m, uint8_t* bytes);

// Decoding, step 1: the mask words of every record, read from the bytes.
template <class Backend>
void read_word_masks(Backend backend, const Stream& stream, const uint8_t* bytes,
                     const EncodedBlock* layout, int64_t blocks, int32_t voxels_per_block,
                     uint32_t* masks);

// Decoding, step 3: block b's stored voxels written to pool slot b (the pools zero beforehand,
// so unobserved voxels stay the never-observed voxel).
template <class Backend>
void read_block_voxels(Backend backend, const Stream& stream, const uint8_t* bytes,
                       const EncodedBlock* layout, const uint32_t* masks,
                       const uint32_t* word_ranks, int64_t blocks, int32_t voxels_per_block,
                       float distance_scale_m, TsdfView tsdf, ColorView color);

}  // namespace covox::io::internal

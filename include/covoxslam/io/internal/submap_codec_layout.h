#pragma once
// The record layout of encoded submaps (submap_codec.h) as the device codec needs it: where each
// block's record lies, how many voxels it stores, whether it carries colour.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "covoxslam/core/index3d.h"
#include "covoxslam/io/submap_codec.h"

namespace covox::io::internal {

// Where one stored block's record lies in the encoded bytes and what it holds.
struct EncodedBlock {
  uint64_t record_offset = 0;  // byte offset of its index field (unused for a dropped block)
  uint32_t observed = 0;       // stored voxels (0: the block is dropped)
  uint32_t color = 0;          // 1 when its record carries colour
};

// The bytes of one block's record: index, flags, mask, distances and weights, colour if any.
inline uint64_t encoded_record_bytes(const EncodedBlock& block, int voxels_per_block) {
  if (block.observed == 0) return 0;
  const uint64_t per_voxel = block.color ? 2 + 2 + 3 + 2 : 2 + 2;
  return sizeof(Index3D) + 1 + static_cast<uint64_t>(voxels_per_block) / 8 +
         per_voxel * block.observed;
}

// The header of an encoded submap of `blocks` stored blocks.
std::vector<uint8_t> encoded_submap_header(int voxels_per_side, float distance_scale_m,
                                           uint64_t blocks);

// Validates encoded bytes as validate_encoded_submap() does and lists their blocks: indices and
// records (offsets from the start of `data`).
EncodedSubmapInfo encoded_block_layout(const uint8_t* data, size_t size, const char* what,
                                       std::vector<Index3D>* indices,
                                       std::vector<EncodedBlock>* layout);

}  // namespace covox::io::internal

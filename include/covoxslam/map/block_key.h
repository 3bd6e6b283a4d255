#pragma once
// Block indices packed into one 64-bit hash-table key.
//
// Each axis gets 21 bits, stored with an offset of 2^20, so the valid block index range is
// [-2^20, 2^20 - 1] = [-1048576, 1048575] per axis. With 8-voxel blocks of 5 cm voxels that is
// +-419 km around the map origin; with 16-voxel blocks of 20 cm voxels +-3355 km. Keys outside
// the range are rejected (and counted) by the hash table, never wrapped onto other blocks.
// Packed keys use the low 63 bits, so the two reserved values below can never be a real key.
#include <cstdint>

#include "covoxslam/core/index3d.h"
#include "covoxslam/core/macros.h"

namespace covox::map {

constexpr int kBlockKeyBitsPerAxis = 21;
constexpr int32_t kMinBlockIndex = -(1 << (kBlockKeyBitsPerAxis - 1));     // -1048576
constexpr int32_t kMaxBlockIndex = (1 << (kBlockKeyBitsPerAxis - 1)) - 1;  //  1048575
constexpr uint64_t kEmptyBlockKey = ~uint64_t(0);                          // bucket never used
constexpr uint64_t kErasedBlockKey = ~uint64_t(0) - 1;   // tombstone left by erase()
constexpr uint64_t kInvalidBlockKey = ~uint64_t(0) - 2;  // an out-of-range index
constexpr uint32_t kInvalidSlot = ~uint32_t(0);

COVOX_HD_INLINE bool block_index_in_range(const Index3D& index) {
  return index.x >= kMinBlockIndex && index.x <= kMaxBlockIndex && index.y >= kMinBlockIndex &&
         index.y <= kMaxBlockIndex && index.z >= kMinBlockIndex && index.z <= kMaxBlockIndex;
}

// Packs a block index; returns kInvalidBlockKey when it is out of range.
COVOX_HD_INLINE uint64_t pack_block_key(const Index3D& index) {
  if (!block_index_in_range(index)) return kInvalidBlockKey;
  constexpr uint64_t kMask = (uint64_t(1) << kBlockKeyBitsPerAxis) - 1;
  const uint64_t x = static_cast<uint64_t>(index.x - kMinBlockIndex) & kMask;
  const uint64_t y = static_cast<uint64_t>(index.y - kMinBlockIndex) & kMask;
  const uint64_t z = static_cast<uint64_t>(index.z - kMinBlockIndex) & kMask;
  return (x << (2 * kBlockKeyBitsPerAxis)) | (y << kBlockKeyBitsPerAxis) | z;
}

COVOX_HD_INLINE Index3D unpack_block_key(uint64_t key) {
  constexpr uint64_t kMask = (uint64_t(1) << kBlockKeyBitsPerAxis) - 1;
  return Index3D(static_cast<int32_t>((key >> (2 * kBlockKeyBitsPerAxis)) & kMask) + kMinBlockIndex,
                 static_cast<int32_t>((key >> kBlockKeyBitsPerAxis) & kMask) + kMinBlockIndex,
                 static_cast<int32_t>(key & kMask) + kMinBlockIndex);
}

COVOX_HD_INLINE bool is_live_block_key(uint64_t key) { return key < kInvalidBlockKey; }

// A 64-bit finaliser (xor-shift-multiply rounds): neighbouring blocks differ in a few low bits of
// each axis field, and the mix spreads those over the whole word so linear probing sees
// independent home buckets.
COVOX_HD_INLINE uint64_t mix_block_key(uint64_t key) {
  key ^= key >> 31;
  key *= 0x7fb5d329728ea185ull;
  key ^= key >> 27;
  key *= 0x81dadef4bc2dd44dull;
  key ^= key >> 33;
  return key;
}

// Maps a hash to [0, bucket_count) with a multiply-high instead of a modulo, so the bucket count
// need not be a power of two (the benchmark sizes tables to exact load factors).
COVOX_HD_INLINE uint64_t home_bucket(uint64_t hash, uint64_t bucket_count) {
#if COVOX_DEVICE_CODE
  return __umul64hi(hash, bucket_count);
#else
  return static_cast<uint64_t>((static_cast<unsigned __int128>(hash) * bucket_count) >> 64);
#endif
}

}  // namespace covox::map

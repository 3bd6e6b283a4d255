#pragma once
// Finds a voxel of a block layer by its global index inside kernels: block index by floor
// division, slot by a hash-table probe, pool index from the slot.
#include <cstdint>

#include "covoxslam/core/index3d.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/map/block_hash_table_view.h"

namespace covox {

struct BlockVoxelIndexer {
  BlockHashTableView blocks;
  int32_t side = 8;

  // Pool index of the voxel, or -1 when its block is not allocated.
  COVOX_HD_INLINE int64_t pool_index(const Index3D& voxel) const {
    const Index3D block(floor_divide(voxel.x, side), floor_divide(voxel.y, side), floor_divide(voxel.z, side));
    const uint64_t key = pack_block_key(block);
    if (key == kInvalidBlockKey) return -1;
    const uint64_t bucket = blocks.find(key);
    if (bucket == kNoBucket) return -1;
    const int64_t local = (voxel.x - block.x * side) + side * ((voxel.y - block.y * side) + side * (voxel.z - block.z * side));
    return static_cast<int64_t>(blocks.slots[bucket]) * side * side * side + local;
  }
};

}  // namespace covox

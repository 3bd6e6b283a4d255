#pragma once
// Finds a voxel of a block layer by its global index inside kernels: block index by floor
// division, slot by a hash-table probe, pool index from the slot.
#include <cstdint>

#include "covoxslam/core/index3d.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/map/block_hash_table_view.h"

namespace covox::map {

// Voxel k of a block (x fastest): its coordinates inside the block, and its global index.
COVOX_HD_INLINE Index3D local_voxel(int64_t k, int32_t side) {
  return Index3D(static_cast<int32_t>(k % side), static_cast<int32_t>((k / side) % side),
                 static_cast<int32_t>(k / (static_cast<int64_t>(side) * side)));
}
COVOX_HD_INLINE Index3D global_voxel(const Index3D& block, int64_t k, int32_t side) {
  const Index3D local = local_voxel(k, side);
  return Index3D(block.x * side + local.x, block.y * side + local.y, block.z * side + local.z);
}

struct BlockVoxelIndexer {
  BlockHashTableView blocks;
  int32_t side = 8;

  // Pool index of the voxel, or -1 when its block is not allocated.
  COVOX_HD_INLINE int64_t pool_index(const Index3D& voxel) const {
    const Index3D block(floor_divide(voxel.x, side), floor_divide(voxel.y, side),
                        floor_divide(voxel.z, side));
    const uint32_t slot = blocks.slot_of(block);
    if (slot == kInvalidSlot) return -1;
    const int64_t local = (voxel.x - block.x * side) +
                          side * ((voxel.y - block.y * side) + side * (voxel.z - block.z * side));
    return static_cast<int64_t>(slot) * side * side * side + local;
  }
};

}  // namespace covox::map

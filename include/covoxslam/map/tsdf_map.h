#pragma once
// TsdfMap: the TSDF and colour voxels of one map (or submap), indexed by one BlockHashTable.
// Both layers share the block index: a block's slot addresses its voxels in both pools, so colour
// costs no second lookup. Voxel pools are SoA and grow with the hash table's slot count.
#include <algorithm>
#include <cstdint>
#include <vector>

#include "covoxslam/core/device.h"
#include "covoxslam/core/index3d.h"
#include "covoxslam/core/soa_container.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/block_hash_table.h"
#include "covoxslam/map/voxels.h"

namespace covox::map {

struct TsdfMapConfig {
  float voxel_size_m = 0.2f;  // edge length of one voxel
  int voxels_per_side = 16;   // voxels along one block edge: 8 or 16
  BlockHashTableConfig block_table;
};

// One allocated block copied to the host (tests, map files, meshing on the host).
struct HostBlock {
  Index3D index;
  std::vector<TsdfVoxel> tsdf;
  std::vector<ColorVoxel> color;
  std::vector<EsdfVoxel> esdf;
};

// Blocks' voxels side by side: block k (index indices[k]) owns voxels [k * n, (k + 1) * n) of each
// array, n the voxels per block. What a map is filled from without one allocation per block.
struct HostVoxels {
  std::vector<Index3D> indices;
  std::vector<TsdfVoxel> tsdf;
  std::vector<ColorVoxel> color;
  std::vector<EsdfVoxel> esdf;  // empty: every ESDF voxel zero
};

// Bits of TsdfMap::block_changed(): integration sets all of them, each consumer clears its own.
enum BlockChange : uint8_t {
  kEsdfPending = 1,
  kMeshPending = 2,
  kAllPending = kEsdfPending | kMeshPending,
};

class TsdfMap {
 public:
  using TsdfStorage = VoxelStorage<TsdfVoxel, Layout::kSoA>;
  using ColorStorage = VoxelStorage<ColorVoxel, Layout::kSoA>;
  using EsdfStorage = VoxelStorage<EsdfVoxel, Layout::kSoA>;

  TsdfMap(Device device, const TsdfMapConfig& config);

  Device device() const { return blocks_.device(); }
  const TsdfMapConfig& config() const { return config_; }
  float voxel_size_m() const { return config_.voxel_size_m; }
  int voxels_per_side() const { return config_.voxels_per_side; }
  int voxels_per_block() const {
    return config_.voxels_per_side * config_.voxels_per_side * config_.voxels_per_side;
  }
  float block_size_m() const { return config_.voxel_size_m * config_.voxels_per_side; }
  int64_t block_count() const { return blocks_.size(); }

  BlockHashTable& blocks() { return blocks_; }
  const BlockHashTable& blocks() const { return blocks_; }
  TsdfStorage& tsdf() { return tsdf_; }
  ColorStorage& color() { return color_; }
  EsdfStorage& esdf() { return esdf_; }
  // Per slot, bits of BlockChange: what has not yet caught up with the block's latest TSDF.
  Buffer<uint8_t>& block_changed() { return block_changed_; }

  // Grows the pools (and per-slot arrays) to hold every slot the block table has handed out;
  // new voxels are zero.
  void ensure_pool_capacity(const Stream& stream);
  // The slots the pools hold voxels for now (at least the table's slot_count() after
  // ensure_pool_capacity()).
  int64_t pool_slots() const {
    return std::min<int64_t>(static_cast<int64_t>(tsdf_.size()) / voxels_per_block(),
                             static_cast<int64_t>(block_changed_.size()));
  }

  // Every allocated block with its voxels, sorted by block index.
  std::vector<HostBlock> snapshot() const;
  // Fills an empty map with `blocks` (as snapshot() returns them); throws covox::Error if the map
  // is not empty or a block has the wrong number of voxels. ESDF voxels are optional.
  void load_blocks(const std::vector<HostBlock>& blocks, const Stream& stream);
  // The same from voxels side by side (distinct block indices in any order); throws covox::Error
  // if the map is not empty or an array's length does not match the indices.
  void load_voxels(const HostVoxels& voxels, const Stream& stream);
  // Allocates `indices` (distinct, any order) in an empty map: block k takes slot k, every voxel
  // of every layer zero, every BlockChange pending. The caller then fills the pools' slots.
  // Throws covox::Error if the map is not empty or the indices are not distinct valid indices.
  void allocate_blocks_in_order(const std::vector<Index3D>& indices, const Stream& stream);

  void clear();
  // Frees the blocks, the voxel pools and the block table's buckets down to a minimal table: a
  // released map holds next to nothing on its device (clear() keeps the buckets), keeps its
  // configuration and grows again when blocks are added.
  void release();
  // What the map holds on its device: the voxel pools of every slot and the block table.
  int64_t device_bytes() const;

 private:
  TsdfMapConfig config_;
  BlockHashTable blocks_;
  TsdfStorage tsdf_;
  ColorStorage color_;
  EsdfStorage esdf_;
  Buffer<uint8_t> block_changed_;
};

}  // namespace covox::map

#include "covoxslam/map/tsdf_map.h"

#include <algorithm>
#include <numeric>
#include <string>

#include "covoxslam/core/error.h"

namespace covox::map {

TsdfMap::TsdfMap(Device device, const TsdfMapConfig& config)
    : config_(config),
      blocks_(device, config.block_table),
      tsdf_(device),
      color_(device),
      esdf_(device),
      block_changed_(device) {
  if (!(config.voxel_size_m > 0.0f)) {
    throw Error("voxel_size_m must be positive, got " + std::to_string(config.voxel_size_m));
  }
  if (config.voxels_per_side != 8 && config.voxels_per_side != 16) {
    throw Error("voxels_per_side must be 8 or 16, got " + std::to_string(config.voxels_per_side));
  }
}

void TsdfMap::ensure_pool_capacity(const Stream& stream) {
  const size_t slots = blocks_.slot_count();
  const size_t needed = slots * voxels_per_block();
  if (tsdf_.size() >= needed) return;
  // Grow geometrically so that a map growing block by block does not copy its pool every frame.
  const size_t grown_slots = std::max(slots, tsdf_.size() / voxels_per_block() * 3 / 2);
  const size_t grown = grown_slots * voxels_per_block();
  tsdf_.resize(grown, stream);
  color_.resize(grown, stream);
  esdf_.resize(grown, stream);
  const size_t old_slots = block_changed_.size();
  block_changed_.resize(grown_slots, stream);
  set_bytes(block_changed_.data() + old_slots, device(), 0, grown_slots - old_slots, stream);
}

std::vector<HostBlock> TsdfMap::snapshot() const {
  Buffer<Index3D> keys(device());
  Buffer<uint32_t> slots(device());
  blocks_.export_entries(&keys, &slots);
  const auto host_keys = keys.to_host();
  const auto host_slots = slots.to_host();
  const auto tsdf = tsdf_.to_host();
  const auto color = color_.to_host();
  const auto esdf = esdf_.to_host();
  std::vector<size_t> order(host_keys.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return host_keys[a] < host_keys[b]; });
  const size_t per_block = static_cast<size_t>(voxels_per_block());
  std::vector<HostBlock> blocks;
  blocks.reserve(order.size());
  for (size_t i : order) {
    HostBlock block;
    block.index = host_keys[i];
    const size_t begin = static_cast<size_t>(host_slots[i]) * per_block;
    block.tsdf.assign(tsdf.begin() + begin, tsdf.begin() + begin + per_block);
    block.color.assign(color.begin() + begin, color.begin() + begin + per_block);
    block.esdf.assign(esdf.begin() + begin, esdf.begin() + begin + per_block);
    blocks.push_back(std::move(block));
  }
  return blocks;
}

void TsdfMap::load_blocks(const std::vector<HostBlock>& blocks, const Stream& stream) {
  if (block_count() != 0) throw Error("TsdfMap::load_blocks: the map is not empty");
  const size_t per_block = static_cast<size_t>(voxels_per_block());
  const bool with_esdf = std::any_of(blocks.begin(), blocks.end(),
                                     [](const HostBlock& block) { return !block.esdf.empty(); });
  HostVoxels voxels;
  voxels.indices.reserve(blocks.size());
  voxels.tsdf.reserve(blocks.size() * per_block);
  voxels.color.reserve(blocks.size() * per_block);
  if (with_esdf) voxels.esdf.reserve(blocks.size() * per_block);
  for (const HostBlock& block : blocks) {
    if (block.tsdf.size() != per_block || block.color.size() != per_block ||
        (!block.esdf.empty() && block.esdf.size() != per_block)) {
      throw Error("TsdfMap::load_blocks: a block does not have " + std::to_string(per_block) +
                  " voxels");
    }
    voxels.indices.push_back(block.index);
    voxels.tsdf.insert(voxels.tsdf.end(), block.tsdf.begin(), block.tsdf.end());
    voxels.color.insert(voxels.color.end(), block.color.begin(), block.color.end());
    if (!with_esdf) continue;
    if (block.esdf.empty()) {
      voxels.esdf.resize(voxels.esdf.size() + per_block);
    } else {
      voxels.esdf.insert(voxels.esdf.end(), block.esdf.begin(), block.esdf.end());
    }
  }
  load_voxels(voxels, stream);
}

void TsdfMap::load_voxels(const HostVoxels& voxels, const Stream& stream) {
  if (block_count() != 0) throw Error("TsdfMap::load_voxels: the map is not empty");
  const size_t count = voxels.indices.size();
  const size_t pool = count * static_cast<size_t>(voxels_per_block());
  if (voxels.tsdf.size() != pool || voxels.color.size() != pool ||
      (!voxels.esdf.empty() && voxels.esdf.size() != pool)) {
    throw Error("TsdfMap::load_voxels: " + std::to_string(count) + " blocks need " +
                std::to_string(pool) + " voxels per layer, got " +
                std::to_string(voxels.tsdf.size()) + " TSDF, " +
                std::to_string(voxels.color.size()) + " colour, " +
                std::to_string(voxels.esdf.size()) + " ESDF");
  }
  allocate_blocks_in_order(voxels.indices, stream);
  tsdf_.copy_from_host(voxels.tsdf, stream);
  color_.copy_from_host(voxels.color, stream);
  if (!voxels.esdf.empty()) esdf_.copy_from_host(voxels.esdf, stream);
  stream.synchronize();
}

void TsdfMap::allocate_blocks_in_order(const std::vector<Index3D>& indices, const Stream& stream) {
  if (block_count() != 0) throw Error("TsdfMap: blocks can be loaded only into an empty map");
  const size_t count = indices.size();
  const size_t pool = count * static_cast<size_t>(voxels_per_block());
  auto keys = Buffer<Index3D>::from_host(device(), indices, stream);
  Buffer<uint32_t> slots(device(), count);
  blocks_.reserve(static_cast<int64_t>(count));
  const ActivateResult result =
      blocks_.activate(keys.data(), static_cast<int64_t>(count), slots.data(), nullptr, stream);
  if (!result.ok() || result.num_new != static_cast<int64_t>(count)) {
    clear();
    throw Error("TsdfMap: the loaded blocks are not distinct valid block indices");
  }
  // In an empty table distinct keys take slots 0..n-1 in input order, so the voxels can be
  // copied as one array. Checked, not assumed.
  const auto host_slots = slots.to_host(stream);
  for (size_t i = 0; i < host_slots.size(); ++i) {
    if (host_slots[i] != i) {
      clear();
      throw Error("TsdfMap: unexpected slot order while loading blocks");
    }
  }
  tsdf_.resize(0, stream);
  tsdf_.resize(pool, stream);
  color_.resize(0, stream);
  color_.resize(pool, stream);
  esdf_.resize(0, stream);
  esdf_.resize(pool, stream);
  block_changed_.resize(count, stream);
  block_changed_.fill_bytes(kAllPending, stream);
}

void TsdfMap::release() {
  BlockHashTableConfig minimal = config_.block_table;
  minimal.initial_bucket_count = 2;  // the smallest table BlockHashTable accepts
  const Device device = this->device();
  blocks_ = BlockHashTable(device, minimal);
  tsdf_ = TsdfStorage(device);
  color_ = ColorStorage(device);
  esdf_ = EsdfStorage(device);
  block_changed_ = Buffer<uint8_t>(device);
}

int64_t TsdfMap::device_bytes() const {
  // The pools are SoA: each field is an array of its own, so a voxel takes its fields' bytes.
  constexpr int64_t kVoxelBytes = (4 + 4) + (1 + 1 + 1 + 4) + (4 + 1 + 1);
  constexpr int64_t kBucketBytes = sizeof(uint64_t) + sizeof(uint32_t);  // packed key, slot
  return pool_slots() * voxels_per_block() * kVoxelBytes +
         static_cast<int64_t>(blocks_.bucket_count()) * kBucketBytes;
}

void TsdfMap::clear() {
  blocks_.clear();
  tsdf_.resize(0);
  color_.resize(0);
  esdf_.resize(0);
  block_changed_.resize(0);
}

}  // namespace covox::map

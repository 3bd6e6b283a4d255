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
  std::vector<Index3D> indices;
  std::vector<TsdfVoxel> tsdf;
  std::vector<ColorVoxel> color;
  std::vector<EsdfVoxel> esdf;
  for (const HostBlock& block : blocks) {
    if (block.tsdf.size() != per_block || block.color.size() != per_block ||
        (!block.esdf.empty() && block.esdf.size() != per_block)) {
      throw Error("TsdfMap::load_blocks: a block does not have " + std::to_string(per_block) +
                  " voxels");
    }
    indices.push_back(block.index);
    tsdf.insert(tsdf.end(), block.tsdf.begin(), block.tsdf.end());
    color.insert(color.end(), block.color.begin(), block.color.end());
    if (block.esdf.empty()) {
      esdf.resize(esdf.size() + per_block);
    } else {
      esdf.insert(esdf.end(), block.esdf.begin(), block.esdf.end());
    }
  }
  auto keys = Buffer<Index3D>::from_host(device(), indices, stream);
  Buffer<uint32_t> slots(device(), indices.size());
  blocks_.reserve(static_cast<int64_t>(indices.size()));
  const ActivateResult result = blocks_.activate(keys.data(), static_cast<int64_t>(indices.size()),
                                                 slots.data(), nullptr, stream);
  if (!result.ok() || result.num_new != static_cast<int64_t>(indices.size())) {
    clear();
    throw Error("TsdfMap::load_blocks: the blocks are not distinct valid block indices");
  }
  // In an empty table distinct keys take slots 0..n-1 in input order, so the voxels can be
  // copied as one array. Checked, not assumed.
  const auto host_slots = slots.to_host(stream);
  for (size_t i = 0; i < host_slots.size(); ++i) {
    if (host_slots[i] != i) {
      clear();
      throw Error("TsdfMap::load_blocks: unexpected slot order");
    }
  }
  tsdf_.copy_from_host(tsdf, stream);
  color_.copy_from_host(color, stream);
  esdf_.copy_from_host(esdf, stream);
  block_changed_.resize(indices.size(), stream);
  block_changed_.fill_bytes(kAllPending, stream);
  stream.synchronize();
}

void TsdfMap::clear() {
  blocks_.clear();
  tsdf_.resize(0);
  color_.resize(0);
  esdf_.resize(0);
  block_changed_.resize(0);
}

}  // namespace covox::map

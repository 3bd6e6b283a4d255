// The submap codec on the map's own device: encode_submap(map) and load_encoded_submap() quantise
// and expand the voxels where they are (submap_codec_kernels.h), so what crosses between host and
// device is the compact bytes, not the full pools.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/io/internal/submap_codec_kernels.h"
#include "covoxslam/io/internal/submap_codec_layout.h"
#include "covoxslam/io/submap_codec.h"

namespace covox::io {
namespace {

constexpr int32_t kVoxelsPerWord = 32;

// The map's blocks in increasing index order: their indices and pool slots.
void blocks_in_index_order(const map::TsdfMap& map, const Stream& stream,
                           std::vector<Index3D>* indices, std::vector<uint32_t>* slots) {
  Buffer<Index3D> keys(map.device());
  Buffer<uint32_t> key_slots(map.device());
  map.blocks().export_entries(&keys, &key_slots);
  const std::vector<Index3D> host_keys = keys.to_host(stream);
  const std::vector<uint32_t> host_slots = key_slots.to_host(stream);
  std::vector<size_t> order(host_keys.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return host_keys[a] < host_keys[b]; });
  indices->clear();
  slots->clear();
  for (size_t i : order) {
    indices->push_back(host_keys[i]);
    slots->push_back(host_slots[i]);
  }
}

// Record offsets (from the start of the block section) for the blocks' counts; the section's
// size is returned, the stored blocks counted.
uint64_t place_records(std::vector<internal::EncodedBlock>* layout, int voxels_per_block,
                       uint64_t* stored) {
  uint64_t offset = 0;
  *stored = 0;
  for (internal::EncodedBlock& block : *layout) {
    block.record_offset = offset;
    offset += internal::encoded_record_bytes(block, voxels_per_block);
    if (block.observed > 0) ++*stored;
  }
  return offset;
}

}  // namespace

std::vector<uint8_t> encode_submap(const map::TsdfMap& map, float distance_scale_m) {
  if (!(std::isfinite(distance_scale_m) && distance_scale_m > 0.0f))
    throw Error("encode_submap: the distance scale must be a positive number of metres");
  const Device device = map.device();
  const Stream stream(device);
  std::vector<Index3D> indices;
  std::vector<uint32_t> slots;
  blocks_in_index_order(map, stream, &indices, &slots);
  const int32_t per_block = map.voxels_per_block();
  const int32_t words = per_block / kVoxelsPerWord;
  const auto blocks = static_cast<int64_t>(indices.size());
  // The pools are only read; their views are non-const because kernels share one view type.
  auto& pools = const_cast<map::TsdfMap&>(map);
  const auto device_slots = Buffer<uint32_t>::from_host(device, slots, stream);
  const auto device_indices = Buffer<Index3D>::from_host(device, indices, stream);
  Buffer<uint32_t> masks(device, static_cast<size_t>(blocks * words));
  Buffer<uint32_t> word_ranks(device, static_cast<size_t>(blocks * words));
  Buffer<uint8_t> word_colors(device, static_cast<size_t>(blocks * words));
  Buffer<internal::EncodedBlock> layout(device, static_cast<size_t>(blocks));
  dispatch(device, [&](auto backend) {
    internal::quantised_word_masks(backend, stream, pools.tsdf().view(), pools.color().view(),
                                   device_slots.data(), blocks, per_block, distance_scale_m,
                                   masks.data(), word_colors.data());
    internal::block_word_ranks(backend, stream, masks.data(), word_colors.data(), blocks, words,
                               word_ranks.data(), layout.data());
  });
  std::vector<internal::EncodedBlock> host_layout = layout.to_host(stream);
  uint64_t stored = 0;
  const uint64_t section_bytes = place_records(&host_layout, per_block, &stored);
  layout.copy_from_host(host_layout, stream);
  Buffer<uint8_t> section(device, static_cast<size_t>(section_bytes));
  dispatch(device, [&](auto backend) {
    internal::write_block_records(backend, stream, pools.tsdf().view(), pools.color().view(),
                                  device_slots.data(), device_indices.data(), layout.data(),
                                  masks.data(), word_ranks.data(), blocks, per_block,
                                  distance_scale_m, section.data());
  });
  std::vector<uint8_t> out =
      internal::encoded_submap_header(map.voxels_per_side(), distance_scale_m, stored);
  const size_t header_bytes = out.size();
  out.resize(header_bytes + section_bytes);
  if (section_bytes > 0) {
    copy_bytes(out.data() + header_bytes, Device::kCpu, section.data(), device, section_bytes,
               stream);
  }
  stream.synchronize();
  return out;
}

void load_encoded_submap(const std::vector<uint8_t>& bytes, map::TsdfMap* map,
                         const Stream& stream) {
  StageProfiler::Scope profile("submap decode", stream);
  std::vector<Index3D> indices;
  std::vector<internal::EncodedBlock> host_layout;
  const EncodedSubmapInfo info = internal::encoded_block_layout(
      bytes.data(), bytes.size(), "load_encoded_submap", &indices, &host_layout);
  if (info.voxels_per_side != map->voxels_per_side())
    throw Error("load_encoded_submap: the submap has " + std::to_string(info.voxels_per_side) +
                " voxels per side, the map " + std::to_string(map->voxels_per_side()));
  map->clear();
  profile.mark("layout");
  map->allocate_blocks_in_order(indices, stream);
  profile.mark("allocate blocks");
  const auto blocks = static_cast<int64_t>(indices.size());
  if (blocks == 0) {
    stream.synchronize();
    return;
  }
  const Device device = map->device();
  const int32_t per_block = map->voxels_per_block();
  const int32_t words = per_block / kVoxelsPerWord;
  const auto device_bytes = Buffer<uint8_t>::from_host(device, bytes, stream);
  const auto layout = Buffer<internal::EncodedBlock>::from_host(device, host_layout, stream);
  profile.mark("upload");
  Buffer<uint32_t> masks(device, static_cast<size_t>(blocks * words));
  Buffer<uint32_t> word_ranks(device, static_cast<size_t>(blocks * words));
  Buffer<internal::EncodedBlock> ranked(device, static_cast<size_t>(blocks));
  dispatch(device, [&](auto backend) {
    internal::read_word_masks(backend, stream, device_bytes.data(), layout.data(), blocks,
                              per_block, masks.data());
    internal::block_word_ranks(backend, stream, masks.data(), nullptr, blocks, words,
                               word_ranks.data(), ranked.data());
    internal::read_block_voxels(backend, stream, device_bytes.data(), layout.data(), masks.data(),
                                word_ranks.data(), blocks, per_block, info.distance_scale_m,
                                map->tsdf().view(), map->color().view());
  });
  stream.synchronize();
  profile.mark("voxels");
}

}  // namespace covox::io

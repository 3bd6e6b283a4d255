#include "covoxslam/io/submap_codec.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "covoxslam/core/bit_count.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/internal/submap_codec_layout.h"
#include "covoxslam/io/internal/voxel_quantisation.h"

namespace covox {
namespace io {
namespace {

constexpr char kMagic[4] = {'C', 'V', 'X', 'S'};
constexpr uint8_t kFlagColor = 1;
constexpr size_t kRecordFlagsAt = sizeof(Index3D);  // a record: index, flags, mask, fields
// Header: magic, version, voxels per side, distance scale, block count.
constexpr size_t kHeaderBytes = 4 + 4 + 4 + 4 + 8;
using internal::dequantise_distance;
using internal::quantise;
using internal::QuantisedVoxel;

template <class T>
void append(std::vector<uint8_t>* out, const T& value) {
  const auto* bytes = reinterpret_cast<const uint8_t*>(&value);
  out->insert(out->end(), bytes, bytes + sizeof(T));
}

void encode_block(const map::HostBlock& block, size_t per_block, double scale_m,
                  std::vector<QuantisedVoxel>* scratch, std::vector<uint8_t>* out) {
  std::vector<QuantisedVoxel>& voxels = *scratch;
  voxels.clear();
  std::vector<uint8_t> mask(per_block / 8, 0);
  bool color = false;
  for (size_t k = 0; k < per_block; ++k) {
    const QuantisedVoxel q = quantise(block.tsdf[k], block.color[k], scale_m);
    if (!q.observed()) continue;
    mask[k / 8] = static_cast<uint8_t>(mask[k / 8] | (1u << (k % 8)));
    color = color || q.has_color();
    voxels.push_back(q);
  }
  if (voxels.empty()) return;  // only never-observed voxels: the block is dropped
  append(out, block.index.x);
  append(out, block.index.y);
  append(out, block.index.z);
  append(out, static_cast<uint8_t>(color ? kFlagColor : 0));
  out->insert(out->end(), mask.begin(), mask.end());
  for (const QuantisedVoxel& q : voxels) append(out, q.distance);
  for (const QuantisedVoxel& q : voxels) append(out, q.weight);
  if (!color) return;
  for (const QuantisedVoxel& q : voxels) {
    out->push_back(q.r);
    out->push_back(q.g);
    out->push_back(q.b);
  }
  for (const QuantisedVoxel& q : voxels) append(out, q.color_weight);
}

// Bounds-checked reading of encoded bytes; every error names `what`.
class ByteReader {
 public:
  ByteReader(const uint8_t* data, size_t size, const char* what)
      : data_(data), size_(size), what_(what) {}
  template <class T>
  T get(const char* field) {
    T value;
    std::memcpy(&value, take(sizeof(T), field), sizeof(T));
    return value;
  }
  const uint8_t* take(size_t bytes, const char* field) {
    if (bytes > size_ - position_) fail(std::string("truncated while reading ") + field);
    const uint8_t* at = data_ + position_;
    position_ += bytes;
    return at;
  }
  size_t remaining() const { return size_ - position_; }
  size_t position() const { return position_; }
  [[noreturn]] void fail(const std::string& message) const {
    throw Error(std::string(what_) + ": " + message);
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t position_ = 0;
  const char* what_;
};

EncodedSubmapInfo read_header(ByteReader& r) {
  const uint8_t* magic = r.take(sizeof(kMagic), "the submap magic");
  if (std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) r.fail("not an encoded submap (magic)");
  const uint32_t version = r.get<uint32_t>("the codec version");
  if (version != kSubmapCodecVersion) {
    r.fail("submap codec version " + std::to_string(version) + ", this build reads version " +
           std::to_string(kSubmapCodecVersion));
  }
  EncodedSubmapInfo info;
  info.voxels_per_side = static_cast<int>(r.get<uint32_t>("voxels per side"));
  info.distance_scale_m = r.get<float>("the distance scale");
  info.blocks = r.get<uint64_t>("the block count");
  if (info.voxels_per_side != 8 && info.voxels_per_side != 16)
    r.fail("voxels per side must be 8 or 16, got " + std::to_string(info.voxels_per_side));
  if (!(std::isfinite(info.distance_scale_m) && info.distance_scale_m > 0.0f))
    r.fail("the distance scale is not a positive number");
  // A block needs at least its index, flags and mask.
  const size_t per_block =
      static_cast<size_t>(info.voxels_per_side) * info.voxels_per_side * info.voxels_per_side;
  if (info.blocks > r.remaining() / (sizeof(Index3D) + 1 + per_block / 8))
    r.fail("the block count is larger than the bytes");
  return info;
}

size_t popcount(const uint8_t* mask, size_t bytes) {
  // Whole 32-bit words first (copied out: the mask has no alignment), then the tail bytes.
  size_t count = 0;
  size_t i = 0;
  for (; i + sizeof(uint32_t) <= bytes; i += sizeof(uint32_t)) {
    uint32_t word = 0;
    std::memcpy(&word, mask + i, sizeof(word));
    count += count_bits(word);
  }
  for (; i < bytes; ++i) count += count_bits(mask[i]);
  return count;
}

// Where a decoded block's voxels go (per_block of each, zeroed beforehand).
struct VoxelDestination {
  map::TsdfVoxel* tsdf;
  map::ColorVoxel* color;
};

// Decodes into one HostBlock per block.
struct BlockListSink {
  std::vector<map::HostBlock>* blocks;
  size_t per_block = 0;
  void begin(const EncodedSubmapInfo& info, size_t voxels_per_block) {
    per_block = voxels_per_block;
    blocks->resize(info.blocks);
  }
  VoxelDestination block(uint64_t b, const Index3D& index) {
    map::HostBlock& block = (*blocks)[b];
    block.index = index;
    block.tsdf.assign(per_block, map::TsdfVoxel());
    block.color.assign(per_block, map::ColorVoxel());
    block.esdf.clear();
    return {block.tsdf.data(), block.color.data()};
  }
};

// Decodes into voxels side by side (map::HostVoxels).
struct FlatSink {
  map::HostVoxels* voxels;
  size_t per_block = 0;
  void begin(const EncodedSubmapInfo& info, size_t voxels_per_block) {
    per_block = voxels_per_block;
    voxels->indices.assign(info.blocks, Index3D());
    voxels->tsdf.assign(info.blocks * per_block, map::TsdfVoxel());
    voxels->color.assign(info.blocks * per_block, map::ColorVoxel());
    voxels->esdf.clear();
  }
  VoxelDestination block(uint64_t b, const Index3D& index) {
    voxels->indices[b] = index;
    return {voxels->tsdf.data() + b * per_block, voxels->color.data() + b * per_block};
  }
};

// Writes the n observed voxels of a block into `to` (zeroed) at the mask's set bits.
void decode_voxels(const uint8_t* mask, size_t per_block, const uint8_t* distances,
                   const uint8_t* weights, const uint8_t* rgb, const uint8_t* color_weights,
                   float distance_scale_m, const VoxelDestination& to) {
  size_t j = 0;
  for (size_t k = 0; k < per_block; ++k) {
    if (((mask[k / 8] >> (k % 8)) & 1u) == 0) continue;
    int16_t distance;
    uint16_t weight;
    std::memcpy(&distance, distances + 2 * j, 2);
    std::memcpy(&weight, weights + 2 * j, 2);
    to.tsdf[k].distance_m = dequantise_distance(distance, distance_scale_m);
    to.tsdf[k].weight = half_to_float(weight);
    if (rgb) {
      uint16_t color_weight;
      std::memcpy(&color_weight, color_weights + 2 * j, 2);
      to.color[k].r = rgb[3 * j];
      to.color[k].g = rgb[3 * j + 1];
      to.color[k].b = rgb[3 * j + 2];
      to.color[k].weight = half_to_float(color_weight);
    }
    ++j;
  }
}

// Reads block `b`; hands its voxels to `sink` when it is not null. `previous` is the index of
// the block before (null for the first): indices must increase.
template <typename Sink>
Index3D read_block(ByteReader& r, const EncodedSubmapInfo& info, const Index3D* previous,
                   uint64_t b, Sink* sink, size_t* observed = nullptr) {
  const size_t per_block =
      static_cast<size_t>(info.voxels_per_side) * info.voxels_per_side * info.voxels_per_side;
  Index3D index;
  index.x = r.get<int32_t>("a block index");
  index.y = r.get<int32_t>("a block index");
  index.z = r.get<int32_t>("a block index");
  if (previous && !(*previous < index)) r.fail("block indices are not in increasing order");
  const uint8_t flags = r.get<uint8_t>("block flags");
  if ((flags & ~kFlagColor) != 0) r.fail("unknown block flags");
  const uint8_t* mask = r.take(per_block / 8, "a block mask");
  const size_t n = popcount(mask, per_block / 8);
  if (n == 0) r.fail("a stored block has no observed voxel");
  if (observed) *observed = n;
  const bool color = (flags & kFlagColor) != 0;
  const uint8_t* distances = r.take(n * 2, "distances");
  const uint8_t* weights = r.take(n * 2, "weights");
  const uint8_t* rgb = color ? r.take(n * 3, "colours") : nullptr;
  const uint8_t* color_weights = color ? r.take(n * 2, "colour weights") : nullptr;
  if (sink) {
    decode_voxels(mask, per_block, distances, weights, rgb, color_weights, info.distance_scale_m,
                  sink->block(b, index));
  }
  return index;
}

template <typename Sink>
EncodedSubmapInfo walk(const uint8_t* data, size_t size, const char* what, Sink* sink) {
  ByteReader r(data, size, what);
  const EncodedSubmapInfo info = read_header(r);
  if (sink) {
    sink->begin(info, static_cast<size_t>(info.voxels_per_side) * info.voxels_per_side *
                          info.voxels_per_side);
  }
  Index3D previous;
  for (uint64_t b = 0; b < info.blocks; ++b) {
    previous = read_block(r, info, b > 0 ? &previous : nullptr, b, sink);
  }
  if (r.remaining() != 0) r.fail("unexpected bytes after the last block");
  return info;
}

}  // namespace

uint16_t float_to_half(float value) { return internal::float_to_half_bits(value); }

float half_to_float(uint16_t half) { return internal::half_bits_to_float(half); }

std::vector<uint8_t> encode_submap(const std::vector<map::HostBlock>& blocks, int voxels_per_side,
                                   float distance_scale_m) {
  if (voxels_per_side != 8 && voxels_per_side != 16)
    throw Error("encode_submap: voxels per side must be 8 or 16");
  if (!(std::isfinite(distance_scale_m) && distance_scale_m > 0.0f))
    throw Error("encode_submap: the distance scale must be a positive number of metres");
  const size_t per_block = static_cast<size_t>(voxels_per_side) * voxels_per_side * voxels_per_side;
  std::vector<uint8_t> out = internal::encoded_submap_header(voxels_per_side, distance_scale_m, 0);
  const size_t count_at = out.size() - sizeof(uint64_t);
  uint64_t stored = 0;
  std::vector<QuantisedVoxel> scratch;
  for (size_t b = 0; b < blocks.size(); ++b) {
    const map::HostBlock& block = blocks[b];
    if (block.tsdf.size() != per_block || block.color.size() != per_block)
      throw Error("encode_submap: a block has the wrong voxel count");
    if (b > 0 && !(blocks[b - 1].index < block.index))
      throw Error("encode_submap: blocks are not sorted by distinct indices");
    const size_t before = out.size();
    encode_block(block, per_block, distance_scale_m, &scratch, &out);
    if (out.size() != before) ++stored;
  }
  std::memcpy(out.data() + count_at, &stored, sizeof(stored));
  return out;
}

EncodedSubmapInfo validate_encoded_submap(const uint8_t* data, size_t size, const char* what) {
  if (size < kHeaderBytes) throw Error(std::string(what) + ": truncated submap header");
  return walk(data, size, what, static_cast<BlockListSink*>(nullptr));
}

std::vector<map::HostBlock> decode_submap(const uint8_t* data, size_t size, const char* what) {
  std::vector<map::HostBlock> blocks;
  BlockListSink sink{&blocks};
  walk(data, size, what, &sink);
  return blocks;
}

EncodedSubmapInfo decode_submap_voxels(const uint8_t* data, size_t size, const char* what,
                                       map::HostVoxels* voxels) {
  FlatSink sink{voxels};
  return walk(data, size, what, &sink);
}

namespace internal {

std::vector<uint8_t> encoded_submap_header(int voxels_per_side, float distance_scale_m,
                                           uint64_t blocks) {
  std::vector<uint8_t> out(kMagic, kMagic + sizeof(kMagic));
  out.reserve(kHeaderBytes);
  append(&out, kSubmapCodecVersion);
  append(&out, static_cast<uint32_t>(voxels_per_side));
  append(&out, distance_scale_m);
  append(&out, blocks);
  return out;
}

EncodedSubmapInfo encoded_block_layout(const uint8_t* data, size_t size, const char* what,
                                       std::vector<Index3D>* indices,
                                       std::vector<EncodedBlock>* layout) {
  if (size < kHeaderBytes) throw Error(std::string(what) + ": truncated submap header");
  ByteReader r(data, size, what);
  const EncodedSubmapInfo info = read_header(r);
  indices->assign(info.blocks, Index3D());
  layout->assign(info.blocks, EncodedBlock());
  for (uint64_t b = 0; b < info.blocks; ++b) {
    const size_t at = r.position();
    size_t observed = 0;
    (*indices)[b] = read_block(r, info, b > 0 ? &(*indices)[b - 1] : nullptr, b,
                               static_cast<BlockListSink*>(nullptr), &observed);
    EncodedBlock& block = (*layout)[b];
    block.record_offset = at;
    block.color = (data[at + kRecordFlagsAt] & kFlagColor) != 0 ? 1 : 0;
    block.observed = static_cast<uint32_t>(observed);
  }
  if (r.remaining() != 0) r.fail("unexpected bytes after the last block");
  return info;
}

}  // namespace internal

}  // namespace io
}  // namespace covox

#include "covoxslam/io/map_file.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <type_traits>

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"

namespace covox {
namespace io {
namespace {

constexpr char kMagic[8] = {'C', 'O', 'V', 'O', 'X', 'M', 'A', 'P'};
constexpr uint32_t kFlagEsdf = 1;

uint64_t fnv1a(const unsigned char* data, size_t size) {
  uint64_t hash = 0xcbf29ce484222325ull;
  for (size_t i = 0; i < size; ++i) {
    hash ^= data[i];
    hash *= 0x100000001b3ull;
  }
  return hash;
}

class Writer {
 public:
  template <class T>
  void put(const T& value) {
    static_assert(std::is_trivially_copyable<T>::value, "plain data only");
    const auto* bytes = reinterpret_cast<const unsigned char*>(&value);
    buffer_.insert(buffer_.end(), bytes, bytes + sizeof(T));
  }
  template <class T>
  void put_array(const std::vector<T>& values) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(values.data());
    buffer_.insert(buffer_.end(), bytes, bytes + values.size() * sizeof(T));
  }
  std::vector<unsigned char>& bytes() { return buffer_; }

 private:
  std::vector<unsigned char> buffer_;
};

class Reader {
 public:
  Reader(const std::vector<unsigned char>& bytes, size_t end, const std::string& path)
      : bytes_(bytes), end_(end), path_(path) {}
  template <class T>
  T get(const char* what) {
    T value;
    need(sizeof(T), what);
    std::memcpy(&value, bytes_.data() + position_, sizeof(T));
    position_ += sizeof(T);
    return value;
  }
  template <class T>
  void get_array(std::vector<T>* values, size_t count, const char* what) {
    need(count * sizeof(T), what);
    values->resize(count);
    std::memcpy(values->data(), bytes_.data() + position_, count * sizeof(T));
    position_ += count * sizeof(T);
  }
  size_t remaining() const { return end_ - position_; }

 private:
  void need(size_t size, const char* what) {
    if (size > end_ - position_) {
      throw Error("map file " + path_ + ": truncated while reading " + what);
    }
  }
  const std::vector<unsigned char>& bytes_;
  size_t end_;
  size_t position_ = 0;
  const std::string& path_;
};

// Voxels are written field by field, not as structs, so padding bytes never reach the file and
// the format does not depend on the compiler's struct layout.
void put_voxels(Writer& w, const HostBlock& block, bool esdf) {
  for (const TsdfVoxel& v : block.tsdf) {
    w.put(v.distance_m);
    w.put(v.weight);
  }
  for (const ColorVoxel& v : block.color) {
    w.put(v.r);
    w.put(v.g);
    w.put(v.b);
    w.put(v.weight);
  }
  if (esdf) {
    for (const EsdfVoxel& v : block.esdf) {
      w.put(v.distance_m);
      w.put(v.observed);
      w.put(v.is_site);
    }
  }
}

void get_voxels(Reader& r, HostBlock* block, size_t per_block, bool esdf) {
  block->tsdf.resize(per_block);
  block->color.resize(per_block);
  for (TsdfVoxel& v : block->tsdf) {
    v.distance_m = r.get<float>("TSDF voxels");
    v.weight = r.get<float>("TSDF voxels");
  }
  for (ColorVoxel& v : block->color) {
    v.r = r.get<uint8_t>("colour voxels");
    v.g = r.get<uint8_t>("colour voxels");
    v.b = r.get<uint8_t>("colour voxels");
    v.weight = r.get<float>("colour voxels");
  }
  if (esdf) {
    block->esdf.resize(per_block);
    for (EsdfVoxel& v : block->esdf) {
      v.distance_m = r.get<float>("ESDF voxels");
      v.observed = r.get<uint8_t>("ESDF voxels");
      v.is_site = r.get<uint8_t>("ESDF voxels");
    }
  }
}

}  // namespace

void save_map_file(const std::string& path, const MapFileContents& contents) {
  const size_t per_block = static_cast<size_t>(contents.voxels_per_side) *
                           contents.voxels_per_side * contents.voxels_per_side;
  Writer w;
  for (char c : kMagic) w.put(c);
  w.put(kMapFileVersion);
  w.put(contents.has_esdf ? kFlagEsdf : 0u);
  w.put(contents.voxel_size_m);
  w.put(static_cast<int32_t>(contents.voxels_per_side));
  w.put(static_cast<uint64_t>(contents.submaps.size()));
  for (const SubmapRecord& submap : contents.submaps) {
    w.put(submap.id);
    const Eigen::Matrix4d pose = submap.T_world_submap.matrix();
    for (int i = 0; i < 16; ++i) w.put(pose(i / 4, i % 4));
    w.put(static_cast<uint64_t>(submap.blocks.size()));
    for (const HostBlock& block : submap.blocks) {
      if (block.tsdf.size() != per_block || block.color.size() != per_block ||
          (contents.has_esdf && block.esdf.size() != per_block)) {
        throw Error("save_map_file: a block of submap " + std::to_string(submap.id) +
                    " has the wrong voxel count");
      }
      w.put(block.index);
      put_voxels(w, block, contents.has_esdf);
    }
  }
  w.put(fnv1a(w.bytes().data(), w.bytes().size()));

  write_file_replacing(path, "save_map_file", /*binary=*/true, [&](std::ostream& file) {
    file.write(reinterpret_cast<const char*>(w.bytes().data()),
               static_cast<std::streamsize>(w.bytes().size()));
  });
}

MapFileContents load_map_file(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw Error("map file " + path + ": cannot open");
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(file)),
                                         std::istreambuf_iterator<char>());
  if (bytes.size() < sizeof(kMagic) || std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0) {
    throw Error("map file " + path + ": not a covoxslam map (wrong magic)");
  }
  if (bytes.size() < sizeof(kMagic) + sizeof(uint64_t) + 2 * sizeof(uint32_t)) {
    throw Error("map file " + path + ": truncated header");
  }
  uint32_t version = 0;
  std::memcpy(&version, bytes.data() + sizeof(kMagic), sizeof(version));
  if (version != kMapFileVersion) {
    throw Error("map file " + path + ": format version " + std::to_string(version) +
                ", this build reads version " + std::to_string(kMapFileVersion));
  }
  const size_t payload = bytes.size() - sizeof(uint64_t);
  uint64_t stored = 0;
  std::memcpy(&stored, bytes.data() + payload, sizeof(stored));
  if (stored != fnv1a(bytes.data(), payload)) {
    throw Error("map file " + path + ": checksum mismatch (the file is truncated or corrupted)");
  }
  Reader r(bytes, payload, path);
  for (size_t i = 0; i < sizeof(kMagic); ++i) r.get<char>("magic");
  r.get<uint32_t>("version");
  MapFileContents contents;
  contents.has_esdf = (r.get<uint32_t>("flags") & kFlagEsdf) != 0;
  contents.voxel_size_m = r.get<float>("voxel size");
  contents.voxels_per_side = r.get<int32_t>("voxels per side");
  if (!(contents.voxel_size_m > 0.0f) ||
      (contents.voxels_per_side != 8 && contents.voxels_per_side != 16)) {
    throw Error("map file " + path + ": invalid voxel size or voxels per side");
  }
  const size_t per_block = static_cast<size_t>(contents.voxels_per_side) *
                           contents.voxels_per_side * contents.voxels_per_side;
  const uint64_t submaps = r.get<uint64_t>("submap count");
  for (uint64_t s = 0; s < submaps; ++s) {
    SubmapRecord submap;
    submap.id = r.get<int64_t>("submap id");
    Eigen::Matrix4d pose;
    for (int i = 0; i < 16; ++i) pose(i / 4, i % 4) = r.get<double>("submap pose");
    submap.T_world_submap.matrix() = pose;
    const uint64_t blocks = r.get<uint64_t>("block count");
    if (blocks > r.remaining() / (sizeof(Index3D) + per_block * 8)) {
      throw Error("map file " + path + ": block count larger than the file");
    }
    submap.blocks.resize(blocks);
    for (HostBlock& block : submap.blocks) {
      block.index = r.get<Index3D>("block index");
      get_voxels(r, &block, per_block, contents.has_esdf);
    }
    contents.submaps.push_back(std::move(submap));
  }
  if (r.remaining() != 0)
    throw Error("map file " + path + ": unexpected bytes after the last submap");
  return contents;
}

std::vector<std::unique_ptr<TsdfMap>> make_maps(const MapFileContents& contents, Device device) {
  std::vector<std::unique_ptr<TsdfMap>> maps;
  for (const SubmapRecord& submap : contents.submaps) {
    auto map = std::make_unique<TsdfMap>(
        device, TsdfMapConfig{contents.voxel_size_m, contents.voxels_per_side, {}});
    map->load_blocks(submap.blocks, Stream(device));
    maps.push_back(std::move(map));
  }
  return maps;
}

}  // namespace io
}  // namespace covox

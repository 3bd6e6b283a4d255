#include "covoxslam/io/map_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <ext/stdio_filebuf.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <type_traits>
#include <utility>

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/rigid_pose_check.h"
#include "covoxslam/io/submap_codec.h"

namespace covox {
namespace io {
namespace {

constexpr char kMagic[8] = {'C', 'O', 'V', 'O', 'X', 'M', 'A', 'P'};
constexpr uint32_t kFlagEsdf = 1;
constexpr uint32_t kVersion1 = 1;

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
void put_voxels(Writer& w, const map::HostBlock& block, bool esdf) {
  for (const map::TsdfVoxel& v : block.tsdf) {
    w.put(v.distance_m);
    w.put(v.weight);
  }
  for (const map::ColorVoxel& v : block.color) {
    w.put(v.r);
    w.put(v.g);
    w.put(v.b);
    w.put(v.weight);
  }
  if (esdf) {
    for (const map::EsdfVoxel& v : block.esdf) {
      w.put(v.distance_m);
      w.put(v.observed);
      w.put(v.is_site);
    }
  }
}

void get_voxels(Reader& r, map::HostBlock* block, size_t per_block, bool esdf) {
  block->tsdf.resize(per_block);
  block->color.resize(per_block);
  for (map::TsdfVoxel& v : block->tsdf) {
    v.distance_m = r.get<float>("TSDF voxels");
    v.weight = r.get<float>("TSDF voxels");
  }
  for (map::ColorVoxel& v : block->color) {
    v.r = r.get<uint8_t>("colour voxels");
    v.g = r.get<uint8_t>("colour voxels");
    v.b = r.get<uint8_t>("colour voxels");
    v.weight = r.get<float>("colour voxels");
  }
  if (esdf) {
    block->esdf.resize(per_block);
    for (map::EsdfVoxel& v : block->esdf) {
      v.distance_m = r.get<float>("ESDF voxels");
      v.observed = r.get<uint8_t>("ESDF voxels");
      v.is_site = r.get<uint8_t>("ESDF voxels");
    }
  }
}

}  // namespace

void save_map_file_version1(const std::string& path, const MapFileContents& contents) {
  const size_t per_block = static_cast<size_t>(contents.voxels_per_side) *
                           contents.voxels_per_side * contents.voxels_per_side;
  Writer w;
  for (char c : kMagic) w.put(c);
  w.put(kVersion1);
  w.put(contents.has_esdf ? kFlagEsdf : 0u);
  w.put(contents.voxel_size_m);
  w.put(static_cast<int32_t>(contents.voxels_per_side));
  w.put(static_cast<uint64_t>(contents.submaps.size()));
  for (const SubmapRecord& submap : contents.submaps) {
    w.put(submap.id);
    const Eigen::Matrix4d pose = submap.T_world_submap.matrix();
    for (int i = 0; i < 16; ++i) w.put(pose(i / 4, i % 4));
    w.put(static_cast<uint64_t>(submap.blocks.size()));
    for (const map::HostBlock& block : submap.blocks) {
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

namespace {

// What a saved pose may be off a rotation: SlamSystem's poses are products of exact rotations,
// off by rounding (~1e-15); a file above this was written by something else or edited.
constexpr double kSubmapPoseTolerance = 1e-6;

// The submap pose of a file, refused (naming the submap) unless rigid within the tolerance.
Eigen::Isometry3d checked_submap_pose(const Eigen::Matrix4d& pose, const std::string& path,
                                      int64_t id) {
  PoseTolerances exact;
  exact.reject_above_error = kSubmapPoseTolerance;
  exact.reorthonormalize_above_error = kSubmapPoseTolerance;  // never repaired, only refused
  return make_rigid_pose(pose, "map file " + path + ": submap " + std::to_string(id) + "'s pose",
                         nullptr, exact);
}

MapFileContents load_version1(std::istream& file, const std::string& path) {
  file.clear();
  file.seekg(0);
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(file)),
                                         std::istreambuf_iterator<char>());
  if (bytes.size() < sizeof(kMagic) + sizeof(uint64_t) + 2 * sizeof(uint32_t)) {
    throw Error("map file " + path + ": truncated header");
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
    submap.T_world_submap = checked_submap_pose(pose, path, submap.id);
    const uint64_t blocks = r.get<uint64_t>("block count");
    if (blocks > r.remaining() / (sizeof(Index3D) + per_block * 8)) {
      throw Error("map file " + path + ": block count larger than the file");
    }
    submap.blocks.resize(blocks);
    for (map::HostBlock& block : submap.blocks) {
      block.index = r.get<Index3D>("block index");
      get_voxels(r, &block, per_block, contents.has_esdf);
    }
    contents.submaps.push_back(std::move(submap));
  }
  if (r.remaining() != 0)
    throw Error("map file " + path + ": unexpected bytes after the last submap");
  return contents;
}

// Sequential reads of a version 2 file with a hard end (the checksum's offset); every error
// names the file and what was being read.
class StreamReader {
 public:
  StreamReader(std::istream& file, uint64_t end, const std::string& path)
      : file_(file), end_(end), path_(path) {}
  template <class T>
  T get(const char* what) {
    T value;
    read(&value, sizeof(T), what);
    return value;
  }
  void read(void* out, uint64_t size, const char* what) {
    if (size > end_ - position_)
      throw Error("map file " + path_ + ": truncated while reading " + what);
    file_.read(static_cast<char*>(out), static_cast<std::streamsize>(size));
    if (!file_) throw Error("map file " + path_ + ": read error while reading " + what);
    position_ += size;
  }
  uint64_t remaining() const { return end_ - position_; }

 private:
  std::istream& file_;
  uint64_t end_;
  uint64_t position_ = 0;
  const std::string& path_;
};

constexpr uint8_t kTagEnd = 0;
constexpr uint8_t kTagSubmap = 1;
constexpr size_t kWriteBufferBytes = size_t{1} << 20;
// Magic, version, flags, voxel size, voxels per side, distance scale.
constexpr uint64_t kVersion2HeaderBytes = 8 + 4 + 4 + 4 + 4 + 4;

uint64_t fnv1a_update(uint64_t hash, const unsigned char* data, size_t size) {
  for (size_t i = 0; i < size; ++i) {
    hash ^= data[i];
    hash *= 0x100000001b3ull;
  }
  return hash;
}

// The first pass over a version 2 file: its checksum, read in chunks. Returns the payload size.
uint64_t check_version2_checksum(std::istream& file, uint64_t file_size, const std::string& path) {
  if (file_size < kVersion2HeaderBytes + 1 + 8 + 8)
    throw Error("map file " + path + ": truncated (shorter than an empty map)");
  const uint64_t payload = file_size - sizeof(uint64_t);
  std::vector<unsigned char> chunk(kWriteBufferBytes);
  uint64_t hash = 0xcbf29ce484222325ull;
  file.seekg(0);
  for (uint64_t done = 0; done < payload;) {
    const size_t size = static_cast<size_t>(std::min<uint64_t>(chunk.size(), payload - done));
    file.read(reinterpret_cast<char*>(chunk.data()), static_cast<std::streamsize>(size));
    if (!file) throw Error("map file " + path + ": read error");
    hash = fnv1a_update(hash, chunk.data(), size);
    done += size;
  }
  uint64_t stored = 0;
  file.read(reinterpret_cast<char*>(&stored), sizeof(stored));
  if (!file || stored != hash)
    throw Error("map file " + path + ": checksum mismatch (the file is truncated or corrupted)");
  return payload;
}

SubmapRecord read_version2_submap(StreamReader& r, const MapFileContents& contents,
                                  const std::string& path, MapFileVoxels voxels) {
  SubmapRecord submap;
  submap.id = r.get<int64_t>("submap id");
  Eigen::Matrix4d pose;
  for (int i = 0; i < 16; ++i) pose(i / 4, i % 4) = r.get<double>("submap pose");
  submap.T_world_submap = checked_submap_pose(pose, path, submap.id);
  const uint64_t size = r.get<uint64_t>("submap length");
  if (size > r.remaining())
    throw Error("map file " + path + ": submap length larger than the file");
  std::vector<uint8_t> encoded(static_cast<size_t>(size));
  r.read(encoded.data(), size, "submap voxels");
  const std::string what = "map file " + path + ": submap " + std::to_string(submap.id);
  const EncodedSubmapInfo info =
      validate_encoded_submap(encoded.data(), encoded.size(), what.c_str());
  if (info.voxels_per_side != contents.voxels_per_side ||
      info.distance_scale_m != contents.distance_scale_m)
    throw Error(what + ": voxels per side or distance scale differ from the file's");
  if (voxels == MapFileVoxels::kDecoded) {
    submap.blocks = decode_submap(encoded, what.c_str());
  } else {
    submap.encoded = std::move(encoded);
  }
  return submap;
}

MapFileContents load_version2(std::istream& file, uint64_t file_size, const std::string& path,
                              MapFileVoxels voxels) {
  const uint64_t payload = check_version2_checksum(file, file_size, path);
  file.clear();
  file.seekg(0);
  StreamReader r(file, payload, path);
  char magic[sizeof(kMagic)];
  r.read(magic, sizeof(magic), "magic");
  r.get<uint32_t>("version");
  MapFileContents contents;
  if (r.get<uint32_t>("flags") != 0) throw Error("map file " + path + ": unknown flags");
  contents.voxel_size_m = r.get<float>("voxel size");
  contents.voxels_per_side = r.get<int32_t>("voxels per side");
  contents.distance_scale_m = r.get<float>("distance scale");
  if (!(contents.voxel_size_m > 0.0f) || !(contents.distance_scale_m > 0.0f) ||
      (contents.voxels_per_side != 8 && contents.voxels_per_side != 16)) {
    throw Error("map file " + path + ": invalid voxel size, voxels per side or distance scale");
  }
  for (;;) {
    const uint8_t tag = r.get<uint8_t>("record tag");
    if (tag == kTagEnd) break;
    if (tag != kTagSubmap) throw Error("map file " + path + ": unknown record tag");
    contents.submaps.push_back(read_version2_submap(r, contents, path, voxels));
  }
  if (r.get<uint64_t>("submap count") != contents.submaps.size())
    throw Error("map file " + path + ": the submap count does not match the records");
  if (r.remaining() != 0)
    throw Error("map file " + path + ": unexpected bytes after the last submap");
  return contents;
}

float largest_distance_m(const MapFileContents& contents) {
  float largest = 0.0f;
  for (const SubmapRecord& submap : contents.submaps) {
    for (const map::HostBlock& block : submap.blocks) {
      for (const map::TsdfVoxel& v : block.tsdf)
        largest = std::max(largest, std::abs(v.distance_m));
    }
  }
  return largest > 0.0f ? largest : 1.0f;
}

}  // namespace

MapFileWriter::MapFileWriter(const std::string& path, float voxel_size_m, int voxels_per_side,
                             float distance_scale_m)
    : MapFileWriter(write_target_for_path(path), voxel_size_m, voxels_per_side, distance_scale_m) {}

MapFileWriter::MapFileWriter(WriteTarget target, float voxel_size_m, int voxels_per_side,
                             float distance_scale_m)
    : path_(target.display),
      voxels_per_side_(voxels_per_side),
      distance_scale_m_(distance_scale_m),
      checksum_(0xcbf29ce484222325ull) {
  if (!(voxel_size_m > 0.0f) || (voxels_per_side != 8 && voxels_per_side != 16) ||
      !(distance_scale_m > 0.0f))
    throw Error("map file " + path_ + ": invalid voxel size, voxels per side or distance scale");
  file_ = std::make_unique<AtomicFile>(std::move(target), "map file");
  buffer_.reserve(kWriteBufferBytes);
  for (char c : kMagic) put(c);
  put(kMapFileVersion);
  put(uint32_t{0});
  put(voxel_size_m);
  put(static_cast<int32_t>(voxels_per_side));
  put(distance_scale_m);
}

// An uncommitted file_ removes its temporary.
MapFileWriter::~MapFileWriter() = default;

void MapFileWriter::put_bytes(const void* data, size_t size) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  checksum_ = fnv1a_update(checksum_, bytes, size);
  while (size > 0) {
    const size_t room = kWriteBufferBytes - buffer_.size();
    const size_t take = std::min(room, size);
    buffer_.insert(buffer_.end(), bytes, bytes + take);
    bytes += take;
    size -= take;
    if (buffer_.size() == kWriteBufferBytes) flush();
  }
}

void MapFileWriter::flush() {
  size_t done = 0;
  while (done < buffer_.size()) {
    const ssize_t wrote = ::write(file_->fd(), buffer_.data() + done, buffer_.size() - done);
    if (wrote < 0 && errno == EINTR) continue;
    if (wrote <= 0) file_->fail("write failed");
    done += static_cast<size_t>(wrote);
  }
  buffer_.clear();
}

void MapFileWriter::add_submap(int64_t id, const Eigen::Isometry3d& T_world_submap,
                               const std::vector<uint8_t>& encoded) {
  if (!file_) throw Error("map file " + path_ + ": add_submap after commit");
  const std::string what = "map file " + path_ + ": submap " + std::to_string(id);
  const EncodedSubmapInfo info =
      validate_encoded_submap(encoded.data(), encoded.size(), what.c_str());
  if (info.voxels_per_side != voxels_per_side_ || info.distance_scale_m != distance_scale_m_)
    throw Error(what + ": encoded with other voxels per side or distance scale than the file's");
  put(kTagSubmap);
  put(id);
  const Eigen::Matrix4d pose = T_world_submap.matrix();
  for (int i = 0; i < 16; ++i) put(pose(i / 4, i % 4));
  put(static_cast<uint64_t>(encoded.size()));
  put_bytes(encoded.data(), encoded.size());
  ++submaps_;
}

void MapFileWriter::commit() {
  if (!file_) throw Error("map file " + path_ + ": committed twice");
  put(kTagEnd);
  put(submaps_);
  const uint64_t checksum = checksum_;
  put(checksum);
  flush();
  file_->commit();
  file_.reset();
}

void save_map_file(const std::string& path, const MapFileContents& contents) {
  const float scale_m =
      contents.distance_scale_m > 0.0f ? contents.distance_scale_m : largest_distance_m(contents);
  MapFileWriter writer(path, contents.voxel_size_m, contents.voxels_per_side, scale_m);
  for (const SubmapRecord& submap : contents.submaps) {
    writer.add_submap(submap.id, submap.T_world_submap,
                      encode_submap(submap.blocks, contents.voxels_per_side, scale_m));
  }
  writer.commit();
}

// A version 1 file's blocks replaced by their compact forms, encoded with its largest |distance|.
MapFileContents encoded_version1(MapFileContents contents) {
  contents.distance_scale_m = largest_distance_m(contents);
  for (SubmapRecord& submap : contents.submaps) {
    submap.encoded =
        encode_submap(submap.blocks, contents.voxels_per_side, contents.distance_scale_m);
    std::vector<map::HostBlock>().swap(submap.blocks);
  }
  return contents;
}

namespace {

// The first bytes of a file that is not a map, printable, for the message.
std::string shown_bytes(const char* bytes, size_t size) {
  std::string shown;
  for (size_t i = 0; i < size; ++i) {
    const auto byte = static_cast<unsigned char>(bytes[i]);
    char hex[8];
    std::snprintf(hex, sizeof(hex), "\\x%02x", byte);
    shown += (byte >= 0x20 && byte < 0x7f) ? std::string(1, bytes[i]) : std::string(hex);
  }
  return shown;
}

}  // namespace

MapFileContents load_map_file(const std::string& path, MapFileVoxels voxels) {
  FileDescriptor file(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (!file.valid()) throw Error("map file " + path + ": cannot open: " + std::strerror(errno));
  return load_map_file(std::move(file), path, voxels);
}

MapFileContents load_map_file(FileDescriptor descriptor, const std::string& path,
                              MapFileVoxels voxels) {
  struct stat status {};
  if (::fstat(descriptor.get(), &status) != 0)
    throw Error("map file " + path + ": cannot read its size: " + std::strerror(errno));
  if (!S_ISREG(status.st_mode))
    throw Error("map file " + path + ": not a regular file (a folder, device or FIFO)");
  const uint64_t file_size = static_cast<uint64_t>(status.st_size);
  constexpr uint64_t kHeaderBytes = sizeof(kMagic) + sizeof(uint32_t);
  if (file_size < kHeaderBytes) {
    throw Error("map file " + path + ": truncated: " + std::to_string(file_size) +
                " bytes, shorter than the " + std::to_string(kHeaderBytes) +
                "-byte header of a covoxslam map");
  }
  __gnu_cxx::stdio_filebuf<char> buffer(descriptor.release(), std::ios::in | std::ios::binary,
                                        kWriteBufferBytes);
  std::istream file(&buffer);
  char magic[sizeof(kMagic)] = {};
  uint32_t version = 0;
  file.read(magic, sizeof(magic));
  file.read(reinterpret_cast<char*>(&version), sizeof(version));
  if (!file)
    throw Error("map file " + path + ": read error in the header: " + std::strerror(errno));
  if (std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
    throw Error("map file " + path + ": not a covoxslam map: it starts with '" +
                shown_bytes(magic, sizeof(magic)) + "', expected 'COVOXMAP'");
  }
  if (version == kVersion1) {
    MapFileContents contents = load_version1(file, path);
    return voxels == MapFileVoxels::kDecoded ? contents : encoded_version1(std::move(contents));
  }
  if (version != kMapFileVersion) {
    throw Error("map file " + path + ": format version " + std::to_string(version) +
                ", this build reads versions 1 and " + std::to_string(kMapFileVersion));
  }
  return load_version2(file, file_size, path, voxels);
}

std::vector<std::unique_ptr<map::TsdfMap>> make_maps(const MapFileContents& contents,
                                                     Device device) {
  std::vector<std::unique_ptr<map::TsdfMap>> maps;
  for (const SubmapRecord& submap : contents.submaps) {
    auto map = std::make_unique<map::TsdfMap>(
        device, map::TsdfMapConfig{contents.voxel_size_m, contents.voxels_per_side, {}});
    map->load_blocks(submap.blocks, Stream(device));
    maps.push_back(std::move(map));
  }
  return maps;
}

}  // namespace io
}  // namespace covox

#pragma once
// Map files: a collection of submaps (TSDF, colour, submap poses, map parameters) in one
// versioned little-endian binary file with a checksum (the layouts: kMapFileVersion below).
// MapFileWriter streams the file submap by submap into a temporary file that is synced and then
// renamed over the target, so a crash never leaves a half-written map under the real name.
// Loading checks magic, version, sizes, every submap's compact form and the checksum before it
// returns anything (reading the file twice, so never holding it whole): a truncated, corrupted or
// foreign file throws covox::Error and the caller's running map is untouched.
#include <Eigen/Geometry>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "covoxslam/core/device.h"
#include "covoxslam/io/atomic_file.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace io {

// Version 2 (written), little-endian: "COVOXMAP" magic, format version (u32), flags (u32, 0),
// voxel size (f32), voxels per side (i32), distance scale (f32, the submap codec's); then one
// record per submap: tag 1 (u8), id (i64), pose T_world_submap (4x4 doubles, row major), the
// length (u64) and bytes of its compact form (io/submap_codec.h); then tag 0 (u8) and the submap
// count (u64); finally the FNV-1a 64 checksum of everything before it. The ESDF is not stored:
// loading recomputes it.
// Version 1 (read only): the same magic, version, flags (bit 0: ESDF stored), voxel size, voxels
// per side, submap count (u64); per submap its id, pose and blocks at full precision (index, then
// TSDF, colour and optionally ESDF voxels field by field); the checksum.
constexpr uint32_t kMapFileVersion = 2;

struct SubmapRecord {
  int64_t id = 0;
  Eigen::Isometry3d T_world_submap = Eigen::Isometry3d::Identity();
  // MapFileVoxels::kDecoded (and save_map_file): as TsdfMap::snapshot() returns them.
  std::vector<map::HostBlock> blocks;
  // MapFileVoxels::kEncoded: the compact form (io/submap_codec.h) with the file's voxels per side
  // and distance scale; `blocks` stays empty.
  std::vector<uint8_t> encoded;
};

// What load_map_file() gives of each submap's voxels.
enum class MapFileVoxels {
  kDecoded,  // blocks at full size: every submap's voxels in memory at once
  kEncoded,  // compact forms as a version 2 file stores them (a tenth of the size or less); a
             // version 1 file's blocks are encoded with its largest |distance| as the scale
};

struct MapFileContents {
  float voxel_size_m = 0.0f;
  int voxels_per_side = 0;
  // The submap codec's distance scale (the TSDF truncation distance). Saving with 0 uses the
  // largest |distance| in the map; loading a version 1 file leaves it 0.
  float distance_scale_m = 0.0f;
  bool has_esdf = false;  // version 1 files only: the blocks carry their ESDF
  std::vector<SubmapRecord> submaps;
};

// Streams a version 2 map file. add_submap() takes each submap's compact form
// (io::encode_submap with the header's voxels per side and distance scale) and writes it at once;
// commit() writes the trailer and checksum, syncs and renames. Destroying an uncommitted writer
// (an exception on the way) removes the temporary and leaves an existing file as it was. Every
// error is a covox::Error naming the file.
class MapFileWriter {
 public:
  MapFileWriter(const std::string& path, float voxel_size_m, int voxels_per_side,
                float distance_scale_m);
  // The same into a checked target (io/output_folder.h), e.g. without overwriting.
  MapFileWriter(WriteTarget target, float voxel_size_m, int voxels_per_side,
                float distance_scale_m);
  ~MapFileWriter();
  MapFileWriter(const MapFileWriter&) = delete;
  MapFileWriter& operator=(const MapFileWriter&) = delete;

  void add_submap(int64_t id, const Eigen::Isometry3d& T_world_submap,
                  const std::vector<uint8_t>& encoded);
  void commit();
  uint64_t submaps_written() const { return submaps_; }

 private:
  void put_bytes(const void* data, size_t size);
  template <class T>
  void put(const T& value) {
    put_bytes(&value, sizeof(T));
  }
  void flush();

  std::string path_;
  std::unique_ptr<AtomicFile> file_;  // null once committed
  int voxels_per_side_ = 0;
  float distance_scale_m_ = 0.0f;
  uint64_t checksum_;
  uint64_t submaps_ = 0;
  std::vector<uint8_t> buffer_;
};

// Writes `contents` as a version 2 file (each submap encoded as it is written).
void save_map_file(const std::string& path, const MapFileContents& contents);
// Writes the retired version 1 layout; kept so that the version 1 reader stays tested.
void save_map_file_version1(const std::string& path, const MapFileContents& contents);
// Loads a version 1 or 2 file (blocks without ESDF voxels, or compact forms: see MapFileVoxels).
// Every submap pose must be rigid (a rotation with determinant +1 within 1e-6, finite values,
// bottom row 0 0 0 1): a file with a valid checksum but a scaled or sheared pose is refused
// naming the submap. Errors name the file, the errno text of a failed call, and what was expected
// against what was found.
MapFileContents load_map_file(const std::string& path,
                              MapFileVoxels voxels = MapFileVoxels::kDecoded);
// The same from a file already opened (io/output_folder.h); `display` names it in messages.
MapFileContents load_map_file(FileDescriptor file, const std::string& display,
                              MapFileVoxels voxels = MapFileVoxels::kDecoded);

// Builds device maps from loaded contents.
std::vector<std::unique_ptr<map::TsdfMap>> make_maps(const MapFileContents& contents,
                                                     Device device);

}  // namespace io
}  // namespace covox

#pragma once
// Map files: a collection of submaps (TSDF, colour, optional ESDF, submap poses, map
// parameters) in one versioned binary file with a checksum.
//
// Layout (little-endian): "COVOXMAP" magic, format version, flags, voxel size, voxels per side,
// submap count; per submap its id, pose T_world_submap (4x4 doubles) and blocks (index then
// voxels); finally the FNV-1a 64 checksum of everything before it. Files are written to a
// temporary file and renamed, so a crash never leaves a half-written map under the real name.
// Loading checks magic, version, sizes and checksum before building anything: a truncated,
// corrupted or foreign file throws covox::Error and the caller's running map is untouched.
#include <Eigen/Geometry>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "covoxslam/core/device.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace io {

constexpr uint32_t kMapFileVersion = 1;

struct SubmapRecord {
  int64_t id = 0;
  Eigen::Isometry3d T_world_submap = Eigen::Isometry3d::Identity();
  std::vector<HostBlock> blocks;  // as TsdfMap::snapshot() returns them
};

struct MapFileContents {
  float voxel_size_m = 0.0f;
  int voxels_per_side = 0;
  bool has_esdf = false;
  std::vector<SubmapRecord> submaps;
};

void save_map_file(const std::string& path, const MapFileContents& contents);
MapFileContents load_map_file(const std::string& path);

// Builds device maps from loaded contents.
std::vector<std::unique_ptr<TsdfMap>> make_maps(const MapFileContents& contents, Device device);

}  // namespace io
}  // namespace covox

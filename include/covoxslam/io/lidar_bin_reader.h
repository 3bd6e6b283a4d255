#pragma once
// Raw float32 LiDAR scans: KITTI Velodyne `.bin` (x, y, z, reflectance per point), the
// x, y, z-only dumps of gtsam_points (kitti_00, kitti_07_dump points.bin, Newer College
// raw/deskewed), and per-point time files (Newer College times_NN.bin). Little-endian float32.
#include <string>
#include <vector>

#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {

enum class BinPointLayout {
  kAutoDetect = 0,    // decide from the file (see detect_bin_point_layout)
  kXyz = 3,           // 3 floats per point
  kXyzIntensity = 4,  // 4 floats per point, the 4th is intensity/reflectance
};

// Decides 3 vs 4 floats per point. The file size settles it when only one stride divides it.
// When both do (every 48 bytes), the content decides: a negative or non-finite value in the
// would-be intensity column rules out 4; otherwise the stride under which consecutive points
// are much closer together wins (drivers write points in scan order, a wrong stride shuffles
// coordinates). Throws covox::Error naming `path` if it stays ambiguous: pass the layout then.
BinPointLayout detect_bin_point_layout(const std::vector<float>& values, const std::string& path);

// Reads a float32 point file. Non-finite points are dropped and counted in `stats`.
PointCloud read_lidar_bin(const std::string& path,
                          BinPointLayout layout = BinPointLayout::kAutoDetect,
                          ReadStats* stats = nullptr);

// Reads a whole file of little-endian float32 values (e.g. Newer College times_NN.bin, one
// time in seconds per point of the matching scan).
std::vector<float> read_float32_file(const std::string& path);

}  // namespace io
}  // namespace covox

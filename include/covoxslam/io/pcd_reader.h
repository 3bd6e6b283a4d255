#pragma once
// PCD point clouds (Point Cloud Library format) in all three DATA encodings:
//  * ascii: one point per line, every field's elements in FIELDS order;
//  * binary: point-major records (all fields of point 0, then point 1, ...);
//  * binary_compressed: uint32 compressed size, uint32 uncompressed size, then LZF data that
//    decompresses to field-major arrays (every point's x, then every point's y, ...).
// x, y, z are required; `intensity` and a packed colour field (`rgb` or `rgba`, 4 bytes, read as
// the bits of a float or a uint32: 0x00RRGGBB) are optional; other fields are skipped. Fields may
// come in any order and with any TYPE/SIZE: values are converted to float.
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {

// Reads a PCD file. Points with a non-finite x, y, z or intensity are dropped and counted in
// `stats` (organised clouds mark missing returns that way). Throws covox::Error naming the file
// for a bad header, missing x/y/z, and truncated or corrupt data.
PointCloud read_pcd(const std::string& path, ReadStats* stats = nullptr);

// The same for a file already in memory; `source_name` is what error messages call it.
PointCloud parse_pcd(const std::vector<uint8_t>& bytes, const std::string& source_name,
                     ReadStats* stats = nullptr);

}  // namespace io
}  // namespace covox

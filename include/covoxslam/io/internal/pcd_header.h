#pragma once
// The header of a PCD file (Point Cloud Library format, v0.5-0.7): which fields each point has,
// how many points, and how the data after the header is encoded.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace covox {
namespace io {

enum class PcdDataEncoding { kAscii, kBinary, kBinaryCompressed };

struct PcdField {
  std::string name;
  int size_bytes = 4;       // 1, 2, 4 or 8
  char type = 'F';          // 'F' float, 'I' signed, 'U' unsigned
  int count = 1;            // elements per point (e.g. 33 for an FPFH histogram)
  size_t offset_bytes = 0;  // of the field's first element within one binary point record

  size_t total_bytes() const { return static_cast<size_t>(size_bytes) * count; }
};

struct PcdHeader {
  std::vector<PcdField> fields;
  size_t width = 0;
  size_t height = 1;  // > 1 for an organised cloud (rows of an image-like sensor)
  size_t point_count = 0;
  PcdDataEncoding encoding = PcdDataEncoding::kAscii;
  size_t data_offset_bytes = 0;   // where the data starts: just after the DATA line
  size_t point_record_bytes = 0;  // sum of all fields' total_bytes()

  // Index into `fields` of the field named `name`, or -1.
  int field_index(const std::string& name) const;
};

// Parses and validates the header at the start of `bytes`. Throws covox::Error naming `path`
// for a missing DATA line, unknown DATA encoding, inconsistent FIELDS/SIZE/TYPE/COUNT lengths,
// unsupported sizes or types, or POINTS != WIDTH * HEIGHT.
PcdHeader parse_pcd_header(const std::vector<uint8_t>& bytes, const std::string& path);

}  // namespace io
}  // namespace covox

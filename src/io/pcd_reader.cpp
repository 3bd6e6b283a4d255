#include "covoxslam/io/pcd_reader.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <string_view>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/internal/lzf_decompress.h"
#include "covoxslam/io/internal/pcd_header.h"
#include "covoxslam/io/internal/text_numbers.h"

namespace covox {
namespace io {
namespace {

// The fields the reader uses, as indices into PcdHeader::fields (-1: absent).
struct UsedFields {
  int x = -1, y = -1, z = -1;
  int intensity = -1;
  int color = -1;  // packed rgb / rgba
};

UsedFields find_used_fields(const PcdHeader& header, const std::string& source) {
  UsedFields used;
  used.x = header.field_index("x");
  used.y = header.field_index("y");
  used.z = header.field_index("z");
  if (used.x < 0 || used.y < 0 || used.z < 0) {
    throw Error("'" + source + "': PCD has no x, y and z fields (a cloud of normals or features?)");
  }
  used.intensity = header.field_index("intensity");
  used.color = header.field_index("rgb");
  if (used.color < 0) used.color = header.field_index("rgba");
  for (int index : {used.x, used.y, used.z, used.intensity}) {
    if (index >= 0 && header.fields[index].count != 1) {
      throw Error("'" + source + "': field '" + header.fields[index].name + "' has COUNT " +
                  std::to_string(header.fields[index].count) + ", expected 1");
    }
  }
  // Packed colour is 4 bytes by definition (PCL stores it as the bits of a float or a uint32);
  // any other size is some unrelated field that happens to be called rgb.
  if (used.color >= 0 &&
      (header.fields[used.color].size_bytes != 4 || header.fields[used.color].count != 1)) {
    log_warning("'", source, "': field '", header.fields[used.color].name,
                "' is not one 4-byte packed colour; colours are not read");
    used.color = -1;
  }
  return used;
}

// One point's worth of the used values, whatever the encoding.
struct PointValues {
  double x = 0.0, y = 0.0, z = 0.0;
  double intensity = 0.0;
  uint32_t packed_color = 0;
};

// Accumulates points, dropping non-finite ones so intensities and colours stay aligned.
class CloudBuilder {
 public:
  CloudBuilder(const UsedFields& used, size_t expected_points) : used_(used) {
    cloud_.points_m.reserve(expected_points);
    if (used.intensity >= 0) cloud_.intensities.reserve(expected_points);
    if (used.color >= 0) cloud_.colors.reserve(expected_points);
  }

  void add(const PointValues& values) {
    const Eigen::Vector3f point(static_cast<float>(values.x), static_cast<float>(values.y),
                                static_cast<float>(values.z));
    const float intensity = static_cast<float>(values.intensity);
    if (!point.allFinite() || (used_.intensity >= 0 && !std::isfinite(intensity))) {
      ++dropped_;
      return;
    }
    cloud_.points_m.push_back(point);
    if (used_.intensity >= 0) cloud_.intensities.push_back(intensity);
    if (used_.color >= 0) {
      const uint32_t bits = values.packed_color;
      cloud_.colors.push_back({static_cast<uint8_t>((bits >> 16) & 0xff),
                               static_cast<uint8_t>((bits >> 8) & 0xff),
                               static_cast<uint8_t>(bits & 0xff)});
    }
  }

  PointCloud finish(const std::string& source, size_t point_count, ReadStats* stats) {
    if (dropped_ > 0) {
      log_info("'", source, "': dropped ", dropped_, " of ", point_count,
               " points with NaN/Inf values");
      if (stats != nullptr) stats->dropped_non_finite_points += dropped_;
    }
    return std::move(cloud_);
  }

 private:
  UsedFields used_;
  PointCloud cloud_;
  size_t dropped_ = 0;
};

template <class T>
T load(const uint8_t* bytes) {
  T value;
  std::memcpy(&value, bytes, sizeof(T));  // memcpy: records are not aligned for T
  return value;
}

// The first element of a binary field as a double (PCD binary data is little-endian, as are all
// hosts we build for).
double decode_number(const uint8_t* bytes, const PcdField& field) {
  switch (field.type) {
    case 'F':
      return field.size_bytes == 4 ? load<float>(bytes) : load<double>(bytes);
    case 'I':
      switch (field.size_bytes) {
        case 1:
          return load<int8_t>(bytes);
        case 2:
          return load<int16_t>(bytes);
        case 4:
          return load<int32_t>(bytes);
        default:
          return static_cast<double>(load<int64_t>(bytes));
      }
    default:  // 'U' (the header parser allows nothing else)
      switch (field.size_bytes) {
        case 1:
          return load<uint8_t>(bytes);
        case 2:
          return load<uint16_t>(bytes);
        case 4:
          return load<uint32_t>(bytes);
        default:
          return static_cast<double>(load<uint64_t>(bytes));
      }
  }
}

// Where a field's values lie in decoded binary data: point i's first element is at
// data + first_byte + i * stride_bytes. Point-major data has the record as stride; field-major
// (decompressed binary_compressed) data has each field's array one after the other.
struct FieldLocation {
  size_t first_byte = 0;
  size_t stride_bytes = 0;
};

PointCloud decode_binary(const uint8_t* data, const PcdHeader& header, const UsedFields& used,
                         bool field_major, const std::string& source, ReadStats* stats) {
  const size_t n = header.point_count;
  auto locate = [&](int index) {
    const PcdField& field = header.fields[index];
    return field_major ? FieldLocation{field.offset_bytes * n, field.total_bytes()}
                       : FieldLocation{field.offset_bytes, header.point_record_bytes};
  };
  const FieldLocation x = locate(used.x), y = locate(used.y), z = locate(used.z);
  const FieldLocation intensity = used.intensity >= 0 ? locate(used.intensity) : FieldLocation{};
  const FieldLocation color = used.color >= 0 ? locate(used.color) : FieldLocation{};

  CloudBuilder builder(used, n);
  for (size_t i = 0; i < n; ++i) {
    PointValues values;
    values.x = decode_number(data + x.first_byte + i * x.stride_bytes, header.fields[used.x]);
    values.y = decode_number(data + y.first_byte + i * y.stride_bytes, header.fields[used.y]);
    values.z = decode_number(data + z.first_byte + i * z.stride_bytes, header.fields[used.z]);
    if (used.intensity >= 0) {
      values.intensity = decode_number(data + intensity.first_byte + i * intensity.stride_bytes,
                                       header.fields[used.intensity]);
    }
    if (used.color >= 0)
      values.packed_color = load<uint32_t>(data + color.first_byte + i * color.stride_bytes);
    builder.add(values);
  }
  return builder.finish(source, n, stats);
}

size_t expected_data_bytes(const PcdHeader& header, const std::string& source) {
  if (header.point_record_bytes != 0 &&
      header.point_count > std::numeric_limits<size_t>::max() / header.point_record_bytes) {
    throw Error("'" + source + "': POINTS x record size overflows: corrupt header");
  }
  return header.point_count * header.point_record_bytes;
}

PointCloud read_binary(const std::vector<uint8_t>& bytes, const PcdHeader& header,
                       const UsedFields& used, const std::string& source, ReadStats* stats) {
  const size_t needed = expected_data_bytes(header, source);
  const size_t available = bytes.size() - header.data_offset_bytes;
  if (available < needed) {
    throw Error("'" + source + "': truncated PCD: " + std::to_string(header.point_count) +
                " points of " + std::to_string(header.point_record_bytes) + " bytes need " +
                std::to_string(needed) + " bytes of data, the file has " +
                std::to_string(available));
  }
  return decode_binary(bytes.data() + header.data_offset_bytes, header, used, false, source, stats);
}

PointCloud read_binary_compressed(const std::vector<uint8_t>& bytes, const PcdHeader& header,
                                  const UsedFields& used, const std::string& source,
                                  ReadStats* stats) {
  const size_t needed = expected_data_bytes(header, source);
  const size_t available = bytes.size() - header.data_offset_bytes;
  constexpr size_t kSizesBytes = 2 * sizeof(uint32_t);
  if (available < kSizesBytes) {
    // PCL writes the two sizes even for an empty cloud, but a missing pair only matters if
    // there are points to read.
    if (header.point_count == 0) return PointCloud();
    throw Error("'" + source + "': truncated PCD: binary_compressed data lacks its two size words");
  }
  const uint8_t* sizes = bytes.data() + header.data_offset_bytes;
  const size_t compressed_bytes = load<uint32_t>(sizes);
  const size_t uncompressed_bytes = load<uint32_t>(sizes + sizeof(uint32_t));
  if (uncompressed_bytes != needed) {
    throw Error("'" + source + "': corrupt PCD: compressed data says it holds " +
                std::to_string(uncompressed_bytes) + " bytes, but " +
                std::to_string(header.point_count) + " points of " +
                std::to_string(header.point_record_bytes) + " bytes are " + std::to_string(needed));
  }
  if (compressed_bytes > available - kSizesBytes) {
    throw Error("'" + source + "': truncated PCD: " + std::to_string(compressed_bytes) +
                " bytes of compressed data announced, " + std::to_string(available - kSizesBytes) +
                " present");
  }
  // LZF turns at most 3 input bytes into 264 output bytes: a size beyond that is a corrupt
  // header, caught here before allocating it.
  constexpr size_t kMaxLzfExpansion = 88;
  if (needed > compressed_bytes * kMaxLzfExpansion + 32) {
    throw Error("'" + source + "': corrupt PCD: " + std::to_string(compressed_bytes) +
                " compressed bytes cannot hold " + std::to_string(needed) + " bytes of points");
  }
  std::vector<uint8_t> decoded(needed);
  lzf_decompress(sizes + kSizesBytes, compressed_bytes, decoded.data(), decoded.size(),
                 "'" + source + "'");
  return decode_binary(decoded.data(), header, used, true, source, stats);
}

// A packed colour written as text: PCL writes it as the decimal uint32 (so no bits are lost in
// printing a float); other writers print the float whose bits are the colour. Digits only means
// the former; anything else is parsed as a number and its float bits taken.
bool parse_packed_color(std::string_view token, const PcdField& field, uint32_t* bits) {
  if (!token.empty() && token.find_first_not_of("0123456789") == std::string_view::npos) {
    uint64_t value = 0;
    const char* end = token.data() + token.size();
    if (std::from_chars(token.data(), end, value).ptr != end || value > 0xffffffffull) return false;
    *bits = static_cast<uint32_t>(value);
    return true;
  }
  double value = 0.0;
  if (!parse_double(token, &value)) return false;
  if (field.type == 'F') {
    const float as_float = static_cast<float>(value);
    std::memcpy(bits, &as_float, sizeof(float));
  } else {
    *bits = static_cast<uint32_t>(static_cast<int64_t>(value));
  }
  return true;
}

PointCloud read_ascii(const std::vector<uint8_t>& bytes, const PcdHeader& header,
                      const UsedFields& used, const std::string& source, ReadStats* stats) {
  // Token position of each field's first element within a line.
  std::vector<size_t> first_token(header.fields.size());
  size_t tokens_per_point = 0;
  for (size_t f = 0; f < header.fields.size(); ++f) {
    first_token[f] = tokens_per_point;
    tokens_per_point += static_cast<size_t>(header.fields[f].count);
  }
  // Line numbers in errors count from the top of the file, as an editor shows them.
  int line_number = 1;
  for (size_t i = 0; i < header.data_offset_bytes; ++i) line_number += bytes[i] == '\n';

  const std::string_view all(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  // Every point takes at least two bytes of text: a corrupt POINTS cannot make us reserve more.
  CloudBuilder builder(used,
                       std::min(header.point_count, (bytes.size() - header.data_offset_bytes) / 2));
  size_t position = header.data_offset_bytes;
  size_t points_read = 0;
  for (; position < all.size() && points_read < header.point_count; ++line_number) {
    size_t line_end = all.find('\n', position);
    if (line_end == std::string_view::npos) line_end = all.size();
    const std::vector<std::string_view> tokens =
        split_whitespace(all.substr(position, line_end - position));
    position = line_end + 1;
    if (tokens.empty()) continue;
    const std::string where = source + ":" + std::to_string(line_number);
    if (tokens.size() != tokens_per_point) {
      throw Error(where + ": expected " + std::to_string(tokens_per_point) +
                  " values per point, found " + std::to_string(tokens.size()));
    }
    auto number = [&](int field) {
      double value = 0.0;
      const std::string_view token = tokens[first_token[field]];
      if (!parse_double(token, &value)) {
        throw Error(where + ": '" + std::string(token) + "' is not a number (field " +
                    header.fields[field].name + ")");
      }
      return value;
    };
    PointValues values;
    values.x = number(used.x);
    values.y = number(used.y);
    values.z = number(used.z);
    if (used.intensity >= 0) values.intensity = number(used.intensity);
    if (used.color >= 0 && !parse_packed_color(tokens[first_token[used.color]],
                                               header.fields[used.color], &values.packed_color)) {
      throw Error(where + ": '" + std::string(tokens[first_token[used.color]]) +
                  "' is not a packed colour");
    }
    builder.add(values);
    ++points_read;
  }
  if (points_read != header.point_count) {
    throw Error("'" + source + "': truncated PCD: header announces " +
                std::to_string(header.point_count) + " points, the ascii data holds " +
                std::to_string(points_read));
  }
  return builder.finish(source, header.point_count, stats);
}

}  // namespace

PointCloud parse_pcd(const std::vector<uint8_t>& bytes, const std::string& source_name,
                     ReadStats* stats) {
  const PcdHeader header = parse_pcd_header(bytes, source_name);
  const UsedFields used = find_used_fields(header, source_name);
  switch (header.encoding) {
    case PcdDataEncoding::kAscii:
      return read_ascii(bytes, header, used, source_name, stats);
    case PcdDataEncoding::kBinary:
      return read_binary(bytes, header, used, source_name, stats);
    case PcdDataEncoding::kBinaryCompressed:
      return read_binary_compressed(bytes, header, used, source_name, stats);
  }
  throw Error("'" + source_name + "': unknown PCD data encoding");
}

PointCloud read_pcd(const std::string& path, ReadStats* stats) {
  return parse_pcd(read_file_bytes(path), path, stats);
}

}  // namespace io
}  // namespace covox

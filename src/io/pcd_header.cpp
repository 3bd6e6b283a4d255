#include "covoxslam/io/pcd_header.h"

#include <algorithm>
#include <charconv>
#include <limits>
#include <string_view>

#include "covoxslam/core/error.h"
#include "covoxslam/io/text_numbers.h"

namespace covox {
namespace io {
namespace {

// A PCD header is a dozen short lines; a "header" longer than this means the file is not a PCD
// (or its DATA line is missing) and we stop instead of scanning megabytes of binary.
constexpr size_t kMaxHeaderBytes = 1 << 20;

struct HeaderLine {
  std::string_view keyword;
  std::vector<std::string_view> values;
  int line_number = 0;
};

size_t parse_count(std::string_view token, const std::string& where) {
  size_t value = 0;
  const char* end = token.data() + token.size();
  if (token.empty() || std::from_chars(token.data(), end, value).ptr != end) {
    throw Error(where + ": '" + std::string(token) + "' is not a non-negative integer");
  }
  return value;
}

void require_length(const HeaderLine& line, size_t expected, const std::string& where) {
  if (line.values.size() != expected) {
    throw Error(where + ": " + std::string(line.keyword) + " has " +
                std::to_string(line.values.size()) + " entries but FIELDS has " +
                std::to_string(expected));
  }
}

PcdDataEncoding parse_encoding(std::string_view token, const std::string& where) {
  if (token == "ascii") return PcdDataEncoding::kAscii;
  if (token == "binary") return PcdDataEncoding::kBinary;
  if (token == "binary_compressed") return PcdDataEncoding::kBinaryCompressed;
  throw Error(where + ": unknown DATA type '" + std::string(token) +
              "' (expected ascii, binary or binary_compressed)");
}

void validate_field(const PcdField& field, const std::string& where) {
  const bool size_ok = field.size_bytes == 1 || field.size_bytes == 2 || field.size_bytes == 4 ||
                       field.size_bytes == 8;
  if (!size_ok) {
    throw Error(where + ": field '" + field.name + "' has SIZE " +
                std::to_string(field.size_bytes) + " (supported: 1, 2, 4, 8)");
  }
  if (field.type != 'F' && field.type != 'I' && field.type != 'U') {
    throw Error(where + ": field '" + field.name + "' has TYPE '" + std::string(1, field.type) +
                "' (supported: F, I, U)");
  }
  if (field.type == 'F' && field.size_bytes != 4 && field.size_bytes != 8) {
    throw Error(where + ": field '" + field.name + "' is a float of " +
                std::to_string(field.size_bytes) + " bytes (supported: 4, 8)");
  }
  if (field.count < 1) throw Error(where + ": field '" + field.name + "' has COUNT < 1");
}

}  // namespace

int PcdHeader::field_index(const std::string& name) const {
  for (size_t i = 0; i < fields.size(); ++i) {
    if (fields[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

PcdHeader parse_pcd_header(const std::vector<uint8_t>& bytes, const std::string& path) {
  const std::string_view all(reinterpret_cast<const char*>(bytes.data()),
                             std::min(bytes.size(), kMaxHeaderBytes));
  std::vector<HeaderLine> lines;
  size_t position = 0;
  int line_number = 0;
  bool found_data_line = false;
  while (position < all.size() && !found_data_line) {
    size_t line_end = all.find('\n', position);
    // The DATA line of an empty ascii file may end the file without a newline.
    const bool last_line = line_end == std::string_view::npos;
    if (last_line) line_end = all.size();
    ++line_number;
    const std::vector<std::string_view> tokens =
        split_whitespace(all.substr(position, line_end - position));
    position = last_line ? all.size() : line_end + 1;
    if (tokens.empty() || tokens.front().front() == '#') continue;
    HeaderLine line;
    line.keyword = tokens.front();
    line.values.assign(tokens.begin() + 1, tokens.end());
    line.line_number = line_number;
    found_data_line = line.keyword == "DATA";
    lines.push_back(std::move(line));
  }
  if (!found_data_line) {
    throw Error("'" + path +
                "': no DATA line in the header: not a PCD file, or the header is truncated");
  }

  PcdHeader header;
  header.data_offset_bytes = position;
  const HeaderLine* fields_line = nullptr;
  const HeaderLine* size_line = nullptr;
  const HeaderLine* type_line = nullptr;
  const HeaderLine* count_line = nullptr;
  bool have_width = false;
  bool have_points = false;
  for (const HeaderLine& line : lines) {
    const std::string where = path + ":" + std::to_string(line.line_number);
    auto single_value = [&]() -> std::string_view {
      if (line.values.size() != 1)
        throw Error(where + ": " + std::string(line.keyword) + " needs one value");
      return line.values.front();
    };
    if (line.keyword == "FIELDS" || line.keyword == "COLUMNS") {  // COLUMNS: the v0.5 name
      fields_line = &line;
    } else if (line.keyword == "SIZE") {
      size_line = &line;
    } else if (line.keyword == "TYPE") {
      type_line = &line;
    } else if (line.keyword == "COUNT") {
      count_line = &line;
    } else if (line.keyword == "WIDTH") {
      header.width = parse_count(single_value(), where);
      have_width = true;
    } else if (line.keyword == "HEIGHT") {
      header.height = parse_count(single_value(), where);
    } else if (line.keyword == "POINTS") {
      header.point_count = parse_count(single_value(), where);
      have_points = true;
    } else if (line.keyword == "DATA") {
      header.encoding = parse_encoding(single_value(), where);
    }
    // VERSION and VIEWPOINT carry nothing the readers use; unknown keywords are tolerated as
    // PCL does, so files from newer writers still load.
  }

  if (fields_line == nullptr || size_line == nullptr || type_line == nullptr) {
    throw Error("'" + path + "': header lacks FIELDS, SIZE or TYPE");
  }
  const size_t field_count = fields_line->values.size();
  if (field_count == 0) throw Error("'" + path + "': FIELDS lists no fields");
  require_length(*size_line, field_count, path + ":" + std::to_string(size_line->line_number));
  require_length(*type_line, field_count, path + ":" + std::to_string(type_line->line_number));
  if (count_line != nullptr) {
    require_length(*count_line, field_count, path + ":" + std::to_string(count_line->line_number));
  }
  for (size_t i = 0; i < field_count; ++i) {
    PcdField field;
    field.name = std::string(fields_line->values[i]);
    const std::string where = path + ":" + std::to_string(size_line->line_number);
    field.size_bytes = static_cast<int>(parse_count(size_line->values[i], where));
    if (type_line->values[i].size() != 1) {
      throw Error(path + ":" + std::to_string(type_line->line_number) + ": TYPE '" +
                  std::string(type_line->values[i]) + "' is not one of F, I, U");
    }
    field.type = type_line->values[i].front();
    if (count_line != nullptr) {
      field.count = static_cast<int>(
          parse_count(count_line->values[i], path + ":" + std::to_string(count_line->line_number)));
    }
    validate_field(field, "'" + path + "'");
    field.offset_bytes = header.point_record_bytes;
    header.point_record_bytes += field.total_bytes();
    header.fields.push_back(std::move(field));
  }

  if (!have_width) throw Error("'" + path + "': header lacks WIDTH");
  if (header.height != 0 && header.width > std::numeric_limits<size_t>::max() / header.height) {
    throw Error("'" + path + "': WIDTH x HEIGHT overflows: corrupt header");
  }
  const size_t width_times_height = header.width * header.height;
  if (!have_points) header.point_count = width_times_height;
  if (header.point_count != width_times_height) {
    throw Error("'" + path + "': POINTS is " + std::to_string(header.point_count) +
                " but WIDTH x HEIGHT is " + std::to_string(header.width) + " x " +
                std::to_string(header.height));
  }
  return header;
}

}  // namespace io
}  // namespace covox

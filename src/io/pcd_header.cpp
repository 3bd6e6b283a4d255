#include "covoxslam/io/internal/pcd_header.h"

#include <algorithm>
#include <charconv>
#include <limits>
#include <string_view>

#include "covoxslam/core/error.h"
#include "covoxslam/io/internal/text_numbers.h"

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

// Splits the header into its non-comment lines, up to and including the DATA line;
// `*position_out` is the byte just past that line (where the data starts).
std::vector<HeaderLine> split_header_lines(const std::vector<uint8_t>& bytes,
                                           const std::string& path, size_t* position_out) {
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
  *position_out = position;
  return lines;
}

// The per-field lines (kept for a second look once FIELDS is known) and whether the optional
// scalar keywords were present.
struct FieldLines {
  const HeaderLine* fields = nullptr;
  const HeaderLine* size = nullptr;
  const HeaderLine* type = nullptr;
  const HeaderLine* count = nullptr;
  bool have_width = false;
  bool have_points = false;
};

std::string_view single_value(const HeaderLine& line, const std::string& where) {
  if (line.values.size() != 1)
    throw Error(where + ": " + std::string(line.keyword) + " needs one value");
  return line.values.front();
}

// Reads the scalar keywords into `header` and remembers where the per-field lines are; a later
// line with the same keyword wins.
FieldLines read_keywords(const std::vector<HeaderLine>& lines, const std::string& path,
                         PcdHeader& header) {
  FieldLines found;
  for (const HeaderLine& line : lines) {
    const std::string where = path + ":" + std::to_string(line.line_number);
    if (line.keyword == "FIELDS" || line.keyword == "COLUMNS") {  // COLUMNS: the v0.5 name
      found.fields = &line;
    } else if (line.keyword == "SIZE") {
      found.size = &line;
    } else if (line.keyword == "TYPE") {
      found.type = &line;
    } else if (line.keyword == "COUNT") {
      found.count = &line;
    } else if (line.keyword == "WIDTH") {
      header.width = parse_count(single_value(line, where), where);
      found.have_width = true;
    } else if (line.keyword == "HEIGHT") {
      header.height = parse_count(single_value(line, where), where);
    } else if (line.keyword == "POINTS") {
      header.point_count = parse_count(single_value(line, where), where);
      found.have_points = true;
    } else if (line.keyword == "DATA") {
      header.encoding = parse_encoding(single_value(line, where), where);
    }
    // VERSION and VIEWPOINT carry nothing the readers use; unknown keywords are tolerated as
    // PCL does, so files from newer writers still load.
  }
  return found;
}

std::string line_place(const std::string& path, const HeaderLine& line) {
  return path + ":" + std::to_string(line.line_number);
}

// Field i from the FIELDS, SIZE, TYPE and (optional) COUNT lines, validated.
PcdField parse_field(const FieldLines& lines, size_t i, const std::string& path) {
  PcdField field;
  field.name = std::string(lines.fields->values[i]);
  field.size_bytes =
      static_cast<int>(parse_count(lines.size->values[i], line_place(path, *lines.size)));
  if (lines.type->values[i].size() != 1) {
    throw Error(line_place(path, *lines.type) + ": TYPE '" + std::string(lines.type->values[i]) +
                "' is not one of F, I, U");
  }
  field.type = lines.type->values[i].front();
  if (lines.count != nullptr) {
    field.count =
        static_cast<int>(parse_count(lines.count->values[i], line_place(path, *lines.count)));
  }
  validate_field(field, "'" + path + "'");
  return field;
}

// Builds the field list and the point record layout (fields packed in order).
void read_fields(const FieldLines& lines, const std::string& path, PcdHeader& header) {
  if (lines.fields == nullptr || lines.size == nullptr || lines.type == nullptr) {
    throw Error("'" + path + "': header lacks FIELDS, SIZE or TYPE");
  }
  const size_t field_count = lines.fields->values.size();
  if (field_count == 0) throw Error("'" + path + "': FIELDS lists no fields");
  require_length(*lines.size, field_count, line_place(path, *lines.size));
  require_length(*lines.type, field_count, line_place(path, *lines.type));
  if (lines.count != nullptr)
    require_length(*lines.count, field_count, line_place(path, *lines.count));
  for (size_t i = 0; i < field_count; ++i) {
    PcdField field = parse_field(lines, i, path);
    field.offset_bytes = header.point_record_bytes;
    header.point_record_bytes += field.total_bytes();
    header.fields.push_back(std::move(field));
  }
}

// POINTS defaults to WIDTH x HEIGHT and, when given, must equal it.
void check_point_count(const FieldLines& lines, const std::string& path, PcdHeader& header) {
  if (!lines.have_width) throw Error("'" + path + "': header lacks WIDTH");
  if (header.height != 0 && header.width > std::numeric_limits<size_t>::max() / header.height) {
    throw Error("'" + path + "': WIDTH x HEIGHT overflows: corrupt header");
  }
  const size_t width_times_height = header.width * header.height;
  if (!lines.have_points) header.point_count = width_times_height;
  if (header.point_count != width_times_height) {
    throw Error("'" + path + "': POINTS is " + std::to_string(header.point_count) +
                " but WIDTH x HEIGHT is " + std::to_string(header.width) + " x " +
                std::to_string(header.height));
  }
}

}  // namespace

int PcdHeader::field_index(const std::string& name) const {
  for (size_t i = 0; i < fields.size(); ++i) {
    if (fields[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

PcdHeader parse_pcd_header(const std::vector<uint8_t>& bytes, const std::string& path) {
  PcdHeader header;
  const std::vector<HeaderLine> lines = split_header_lines(bytes, path, &header.data_offset_bytes);
  const FieldLines field_lines = read_keywords(lines, path, header);
  read_fields(field_lines, path, header);
  check_point_count(field_lines, path, header);
  return header;
}

}  // namespace io
}  // namespace covox

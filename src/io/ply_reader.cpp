#include "covoxslam/io/ply_reader.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string_view>

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/internal/text_numbers.h"

namespace covox {
namespace io {
namespace {

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType type = PlyType::kFloat32;      // the value type (of the items, for a list)
  PlyType count_type = PlyType::kUint8;  // lists only
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;
};

enum class PlyFormat { kAscii, kBinaryLittleEndian };

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  size_t data_offset_bytes = 0;
};

bool parse_type(std::string_view name, PlyType* type) {
  // Both the classic names and the sized aliases later writers use.
  static const std::pair<std::string_view, PlyType> kNames[] = {
      {"char", PlyType::kInt8},      {"int8", PlyType::kInt8},       {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},    {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16},  {"uint16", PlyType::kUint16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},    {"uint", PlyType::kUint32},     {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32},  {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  for (const auto& [text, value] : kNames) {
    if (name == text) {
      *type = value;
      return true;
    }
  }
  return false;
}

size_t type_bytes(PlyType type) {
  switch (type) {
    case PlyType::kInt8:
    case PlyType::kUint8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUint16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32:
      return 4;
    default:
      return 8;
  }
}

bool is_float(PlyType type) { return type == PlyType::kFloat32 || type == PlyType::kFloat64; }

using Tokens = std::vector<std::string_view>;

// "format ascii|binary_little_endian <version>"; `where` names the file and line.
PlyFormat parse_format_line(const Tokens& tokens, const std::string& where) {
  if (tokens.size() < 2) throw Error(where + ": format line without a format");
  if (tokens[1] == "ascii") return PlyFormat::kAscii;
  if (tokens[1] == "binary_little_endian") return PlyFormat::kBinaryLittleEndian;
  throw Error(where + ": PLY format '" + std::string(tokens[1]) +
              "' is not supported (ascii and binary_little_endian are)");
}

// "element <name> <count>".
PlyElement parse_element_line(const Tokens& tokens, const std::string& where) {
  PlyElement element;
  const char* count_end = tokens.size() == 3 ? tokens[2].data() + tokens[2].size() : nullptr;
  if (tokens.size() != 3 ||
      std::from_chars(tokens[2].data(), count_end, element.count).ptr != count_end) {
    throw Error(where + ": expected 'element <name> <count>'");
  }
  element.name = std::string(tokens[1]);
  return element;
}

// "property <type> <name>" or "property list <count type> <type> <name>" (an integer count).
PlyProperty parse_property_line(const Tokens& tokens, const std::string& where) {
  PlyProperty property;
  bool ok = false;
  if (tokens.size() == 5 && tokens[1] == "list") {
    property.is_list = true;
    ok = parse_type(tokens[2], &property.count_type) && parse_type(tokens[3], &property.type) &&
         !is_float(property.count_type);
    property.name = std::string(tokens[4]);
  } else if (tokens.size() == 3) {
    ok = parse_type(tokens[1], &property.type);
    property.name = std::string(tokens[2]);
  }
  if (!ok) throw Error(where + ": cannot parse property line");
  return property;
}

PlyHeader parse_header(const std::vector<uint8_t>& bytes, const std::string& path) {
  const std::string_view all(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  if (all.substr(0, 3) != "ply" || (all.size() > 3 && all[3] != '\n' && all[3] != '\r')) {
    throw Error("'" + path + "' is not a PLY file (it does not start with 'ply')");
  }
  PlyHeader header;
  bool have_format = false;
  size_t position = 0;
  int line_number = 0;
  while (true) {
    const size_t line_end = all.find('\n', position);
    if (line_end == std::string_view::npos) {
      throw Error("'" + path + "': PLY header has no end_header line (truncated file?)");
    }
    ++line_number;
    const Tokens tokens = split_whitespace(all.substr(position, line_end - position));
    position = line_end + 1;
    const std::string where = path + ":" + std::to_string(line_number);
    if (tokens.empty() || tokens[0] == "comment" || tokens[0] == "obj_info" || tokens[0] == "ply")
      continue;
    if (tokens[0] == "end_header") break;
    if (tokens[0] == "format") {
      header.format = parse_format_line(tokens, where);
      have_format = true;
    } else if (tokens[0] == "element") {
      header.elements.push_back(parse_element_line(tokens, where));
    } else if (tokens[0] == "property") {
      if (header.elements.empty()) throw Error(where + ": property before any element");
      header.elements.back().properties.push_back(parse_property_line(tokens, where));
    } else {
      throw Error(where + ": unknown PLY header keyword '" + std::string(tokens[0]) + "'");
    }
  }
  if (!have_format) throw Error("'" + path + "': PLY header has no format line");
  header.data_offset_bytes = position;
  return header;
}

// Reads values one at a time from the body, in either encoding.
class ValueReader {
 public:
  ValueReader(const std::vector<uint8_t>& bytes, size_t offset, PlyFormat format,
              const std::string& path)
      : bytes_(bytes), position_(offset), format_(format), path_(path) {}

  double next(PlyType type) {
    return format_ == PlyFormat::kAscii ? next_ascii() : next_binary(type);
  }

 private:
  template <class T>
  double load() {
    T value;
    std::memcpy(&value, bytes_.data() + position_,
                sizeof(T));  // unaligned; hosts are little-endian
    position_ += sizeof(T);
    return static_cast<double>(value);
  }

  double next_binary(PlyType type) {
    if (type_bytes(type) > bytes_.size() - position_) {
      throw Error("'" + path_ + "': PLY data is truncated (ends at byte " +
                  std::to_string(bytes_.size()) + ")");
    }
    switch (type) {
      case PlyType::kInt8:
        return load<int8_t>();
      case PlyType::kUint8:
        return load<uint8_t>();
      case PlyType::kInt16:
        return load<int16_t>();
      case PlyType::kUint16:
        return load<uint16_t>();
      case PlyType::kInt32:
        return load<int32_t>();
      case PlyType::kUint32:
        return load<uint32_t>();
      case PlyType::kFloat32:
        return load<float>();
      default:
        return load<double>();
    }
  }

  double next_ascii() {
    const std::string_view all(reinterpret_cast<const char*>(bytes_.data()), bytes_.size());
    const size_t begin = all.find_first_not_of(" \t\r\n", position_);
    if (begin == std::string_view::npos)
      throw Error("'" + path_ +
                  "': PLY data is truncated (fewer values than the header announces)");
    size_t end = all.find_first_of(" \t\r\n", begin);
    if (end == std::string_view::npos) end = all.size();
    position_ = end;
    double value = 0.0;
    if (!parse_double(all.substr(begin, end - begin), &value)) {
      throw Error("'" + path_ + "': '" + std::string(all.substr(begin, end - begin)) +
                  "' in the PLY data is not a number");
    }
    return value;
  }

  const std::vector<uint8_t>& bytes_;
  size_t position_;
  PlyFormat format_;
  const std::string& path_;
};

int property_index(const PlyElement& element, std::initializer_list<std::string_view> names) {
  for (size_t i = 0; i < element.properties.size(); ++i) {
    for (std::string_view name : names) {
      if (element.properties[i].name == name) return static_cast<int>(i);
    }
  }
  return -1;
}

uint8_t color_channel(double value, PlyType type) {
  // Float colours are in [0, 1] by convention, integer ones in [0, 255].
  const double scaled = is_float(type) ? value * 255.0 : value;
  if (!std::isfinite(scaled)) return 0;
  return static_cast<uint8_t>(std::clamp(std::lround(scaled), 0L, 255L));
}

// Where the mesh's columns sit among an element's properties (-1: absent). The vertex element
// gives x, y, z and optionally all three colour channels; the face element its index list.
struct MeshColumns {
  int x = -1, y = -1, z = -1, red = -1, green = -1, blue = -1, indices = -1;
};

MeshColumns vertex_columns(const PlyElement& element, const std::string& path) {
  MeshColumns columns;
  columns.x = property_index(element, {"x"});
  columns.y = property_index(element, {"y"});
  columns.z = property_index(element, {"z"});
  if (columns.x < 0 || columns.y < 0 || columns.z < 0)
    throw Error("'" + path + "': PLY vertex element lacks x, y or z");
  columns.red = property_index(element, {"red", "r"});
  columns.green = property_index(element, {"green", "g"});
  columns.blue = property_index(element, {"blue", "b"});
  if (columns.red < 0 || columns.green < 0 || columns.blue < 0)
    columns.red = columns.green = columns.blue = -1;
  return columns;
}

MeshColumns face_columns(const PlyElement& element, const std::string& path) {
  MeshColumns columns;
  columns.indices = property_index(element, {"vertex_indices", "vertex_index"});
  if (columns.indices >= 0 && !element.properties[columns.indices].is_list) columns.indices = -1;
  if (columns.indices < 0)
    throw Error("'" + path + "': PLY face element has no vertex_indices list");
  return columns;
}

// Reads one list property's items; those of the face index list (`keep`) go to `corners`.
void read_list(ValueReader& reader, const PlyElement& element, const PlyProperty& property,
               bool keep, size_t row, std::vector<uint32_t>& corners, const std::string& path) {
  const double count = reader.next(property.count_type);
  if (!(count >= 0.0))
    throw Error("'" + path + "': negative list length in element " + element.name);
  if (keep) corners.clear();
  for (size_t item = 0; item < static_cast<size_t>(count); ++item) {
    const double value = reader.next(property.type);
    if (!keep) continue;
    if (!(value >= 0.0) || value >= 4294967296.0) {
      throw Error("'" + path + "': face " + std::to_string(row) + " has vertex index " +
                  std::to_string(value));
    }
    corners.push_back(static_cast<uint32_t>(value));
  }
}

// Reads one row of an element: scalar properties into `values`, the face index list (the
// property at `indices`) into `corners`; other lists are read past.
void read_row(ValueReader& reader, const PlyElement& element, int indices, size_t row,
              std::vector<double>& values, std::vector<uint32_t>& corners,
              const std::string& path) {
  for (size_t p = 0; p < element.properties.size(); ++p) {
    const PlyProperty& property = element.properties[p];
    if (property.is_list) {
      read_list(reader, element, property, static_cast<int>(p) == indices, row, corners, path);
    } else {
      values[p] = reader.next(property.type);
    }
  }
}

void append_vertex(const PlyElement& element, const MeshColumns& columns,
                   const std::vector<double>& values, size_t row, map::Mesh& mesh,
                   const std::string& path) {
  const Vec3f vertex(static_cast<float>(values[columns.x]), static_cast<float>(values[columns.y]),
                     static_cast<float>(values[columns.z]));
  if (!vertex.is_finite()) {
    throw Error("'" + path + "': vertex " + std::to_string(row) + " has a non-finite coordinate");
  }
  mesh.vertices_m.push_back(vertex);
  if (columns.red < 0) return;
  const auto channel = [&](int column) {
    return color_channel(values[column], element.properties[column].type);
  };
  mesh.colors.push_back(Rgb8{channel(columns.red), channel(columns.green), channel(columns.blue)});
}

// Polygons become a fan around their first corner; degenerate faces (< 3 corners) are skipped,
// as viewers do.
void append_face(const std::vector<uint32_t>& corners, map::Mesh& mesh) {
  for (size_t corner = 2; corner < corners.size(); ++corner) {
    mesh.triangles.insert(mesh.triangles.end(), {corners[0], corners[corner - 1], corners[corner]});
  }
}

// Reads every row of one element, keeping the vertices or faces when it is one of those.
// `max_rows` bounds the reservations: every row takes at least one byte, so a corrupt element
// count cannot make us reserve more than the body could hold. `values` is the row buffer, shared
// by all elements.
void read_element(ValueReader& reader, const PlyElement& element, size_t max_rows,
                  std::vector<double>& values, map::Mesh& mesh, const std::string& path) {
  const bool is_vertex = element.name == "vertex";
  const bool is_face = element.name == "face";
  MeshColumns columns;
  if (is_vertex) {
    columns = vertex_columns(element, path);
    mesh.vertices_m.reserve(std::min(element.count, max_rows));
    if (columns.red >= 0) mesh.colors.reserve(std::min(element.count, max_rows));
  } else if (is_face) {
    columns = face_columns(element, path);
    mesh.triangles.reserve(3 * std::min(element.count, max_rows));
  }
  // An element without properties occupies no bytes; looping over a corrupt count of them
  // would only burn time.
  if (element.properties.empty()) return;
  values.resize(element.properties.size());
  std::vector<uint32_t> corners;
  for (size_t row = 0; row < element.count; ++row) {
    read_row(reader, element, columns.indices, row, values, corners, path);
    if (is_vertex) {
      append_vertex(element, columns, values, row, mesh, path);
    } else if (is_face) {
      append_face(corners, mesh);
    }
  }
}

void check_face_indices(const map::Mesh& mesh, const std::string& path) {
  for (uint32_t index : mesh.triangles) {
    if (index >= mesh.vertices_m.size()) {
      throw Error("'" + path + "': face refers to vertex " + std::to_string(index) +
                  " but there are only " + std::to_string(mesh.vertices_m.size()));
    }
  }
}

}  // namespace

map::Mesh read_mesh_ply(const std::string& path) {
  const std::vector<uint8_t> bytes = read_file_bytes(path);
  const PlyHeader header = parse_header(bytes, path);
  ValueReader reader(bytes, header.data_offset_bytes, header.format, path);
  const size_t max_rows = bytes.size() - header.data_offset_bytes;
  map::Mesh mesh;
  bool have_vertices = false;
  std::vector<double> values;
  for (const PlyElement& element : header.elements) {
    read_element(reader, element, max_rows, values, mesh, path);
    have_vertices = have_vertices || element.name == "vertex";
  }
  if (!have_vertices) throw Error("'" + path + "': PLY file has no vertex element");
  check_face_indices(mesh, path);
  return mesh;
}

}  // namespace io
}  // namespace covox

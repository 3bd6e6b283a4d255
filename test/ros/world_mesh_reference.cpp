// The demo-flight ESDF rostest's ground truth: world.ply's triangles, exact point-to-triangle
// distances and segment-triangle crossings over a grid of cells (world_mesh_reference.h).
#include "world_mesh_reference.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace covox_rostest {

namespace {

size_t ply_type_size(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" ||
      type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  throw std::runtime_error("unknown PLY property type '" + type + "'");
}

struct PlyHeader {
  size_t vertices = 0, faces = 0, vertex_stride = 0;
  std::vector<std::string> vertex_properties;
  bool faces_as_uchar_int_list = false;
};

PlyHeader read_ply_header(std::istream& file, const std::string& path) {
  PlyHeader header;
  std::string line, element;
  std::getline(file, line);
  if (line != "ply") throw std::runtime_error(path + ": not a PLY file");
  while (std::getline(file, line) && line != "end_header") {
    std::istringstream words(line);
    std::string word;
    words >> word;
    if (word == "format" && line != "format binary_little_endian 1.0")
      throw std::runtime_error(path + ": '" + line + "', expected binary_little_endian 1.0");
    if (word == "element")
      words >> element >> (element == "vertex" ? header.vertices : header.faces);
    if (word != "property") continue;
    std::string type, name;
    words >> type;
    if (element == "vertex") {
      words >> name;
      header.vertex_properties.push_back(type + " " + name);
      header.vertex_stride += ply_type_size(type);
    } else if (element == "face") {
      header.faces_as_uchar_int_list = line == "property list uchar int vertex_indices";
    }
  }
  const std::vector<std::string> xyz = {"float x", "float y", "float z"};
  if (header.vertex_properties.size() < 3 ||
      !std::equal(xyz.begin(), xyz.end(), header.vertex_properties.begin()))
    throw std::runtime_error(path + ": vertices do not start with float x, y, z");
  if (!header.faces_as_uchar_int_list)
    throw std::runtime_error(path + ": faces are not 'list uchar int vertex_indices'");
  return header;
}

}  // namespace

std::vector<WorldTriangle> read_world_ply(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw std::runtime_error(path + ": cannot be opened");
  const PlyHeader header = read_ply_header(file, path);
  std::vector<char> vertex_bytes(header.vertices * header.vertex_stride);
  file.read(vertex_bytes.data(), static_cast<std::streamsize>(vertex_bytes.size()));
  std::vector<Eigen::Vector3d> vertices(header.vertices);
  for (size_t i = 0; i < header.vertices; ++i) {
    float xyz[3];
    std::memcpy(xyz, vertex_bytes.data() + i * header.vertex_stride, sizeof(xyz));
    vertices[i] = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
  }
  std::vector<WorldTriangle> triangles;
  triangles.reserve(header.faces);
  for (size_t f = 0; f < header.faces; ++f) {
    unsigned char count = 0;
    int32_t index[3];
    file.read(reinterpret_cast<char*>(&count), 1);
    if (count != 3)
      throw std::runtime_error(path + ": face " + std::to_string(f) + " is no triangle");
    file.read(reinterpret_cast<char*>(index), sizeof(index));
    for (int32_t i : index)
      if (i < 0 || static_cast<size_t>(i) >= header.vertices)
        throw std::runtime_error(path + ": face " + std::to_string(f) + " names vertex " +
                                 std::to_string(i));
    triangles.push_back({vertices[index[0]], vertices[index[1]], vertices[index[2]]});
  }
  if (!file)
    throw std::runtime_error(path + ": ends before its " + std::to_string(header.faces) + " faces");
  return triangles;
}

// The Voronoi regions of the corners, then of the edges, then the face (barycentric coordinates
// of the projection decide which one holds the nearest point).
Eigen::Vector3d closest_point_on_triangle(const WorldTriangle& t, const Eigen::Vector3d& p) {
  const Eigen::Vector3d ab = t.b - t.a, ac = t.c - t.a, ap = p - t.a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return t.a;
  const Eigen::Vector3d bp = p - t.b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return t.b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return t.a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3d cp = p - t.c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return t.c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return t.a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0)
    return t.b + (t.c - t.b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denominator = 1.0 / (va + vb + vc);
  return t.a + ab * (vb * denominator) + ac * (vc * denominator);
}

Eigen::Vector3d triangle_normal(const WorldTriangle& t) {
  return (t.b - t.a).cross(t.c - t.a).normalized();
}

namespace {

// The segment's parameter in (0, 1) where it crosses the triangle's plane inside the triangle
// (Moller-Trumbore), or a negative value.
double segment_crossing(const WorldTriangle& t, const Eigen::Vector3d& origin,
                        const Eigen::Vector3d& delta) {
  const Eigen::Vector3d e1 = t.b - t.a, e2 = t.c - t.a;
  const Eigen::Vector3d q = delta.cross(e2);
  const double det = e1.dot(q);
  if (std::abs(det) < 1e-12) return -1.0;
  const Eigen::Vector3d s = origin - t.a;
  const double u = s.dot(q) / det;
  if (u < 0.0 || u > 1.0) return -1.0;
  const Eigen::Vector3d r = s.cross(e1);
  const double v = delta.dot(r) / det;
  if (v < 0.0 || u + v > 1.0) return -1.0;
  return e2.dot(r) / det;
}

}  // namespace

WorldMesh::WorldMesh(std::vector<WorldTriangle> triangles, double cell_m)
    : triangles_(std::move(triangles)), cell_m_(cell_m), visit_stamp_(triangles_.size(), 0) {
  for (uint32_t i = 0; i < triangles_.size(); ++i) {
    const WorldTriangle& t = triangles_[i];
    const Eigen::Vector3i low = cell_of(t.a.cwiseMin(t.b).cwiseMin(t.c));
    const Eigen::Vector3i high = cell_of(t.a.cwiseMax(t.b).cwiseMax(t.c));
    for (int x = low.x(); x <= high.x(); ++x)
      for (int y = low.y(); y <= high.y(); ++y)
        for (int z = low.z(); z <= high.z(); ++z) cells_[key({x, y, z})].push_back(i);
  }
}

Eigen::Vector3i WorldMesh::cell_of(const Eigen::Vector3d& p) const {
  return (p / cell_m_).array().floor().cast<int>();
}

int64_t WorldMesh::key(const Eigen::Vector3i& cell) {
  const auto part = [](int v) { return static_cast<int64_t>(v + (1 << 20)) & ((1 << 21) - 1); };
  return (part(cell.x()) << 42) | (part(cell.y()) << 21) | part(cell.z());
}

std::vector<uint32_t> WorldMesh::triangles_in(const Eigen::Vector3d& low,
                                              const Eigen::Vector3d& high) const {
  ++query_;
  std::vector<uint32_t> found;
  const Eigen::Vector3i a = cell_of(low), b = cell_of(high);
  for (int x = a.x(); x <= b.x(); ++x)
    for (int y = a.y(); y <= b.y(); ++y)
      for (int z = a.z(); z <= b.z(); ++z) {
        const auto cell = cells_.find(key({x, y, z}));
        if (cell == cells_.end()) continue;
        for (uint32_t i : cell->second) {
          if (visit_stamp_[i] == query_) continue;
          visit_stamp_[i] = query_;
          found.push_back(i);
        }
      }
  return found;
}

double WorldMesh::distance(const Eigen::Vector3d& p, double max_m, Eigen::Vector3d* nearest,
                           Eigen::Vector3d* normal) const {
  const Eigen::Vector3d reach = Eigen::Vector3d::Constant(max_m);
  double shortest = max_m + 1.0;
  for (uint32_t i : triangles_in(p - reach, p + reach)) {
    const Eigen::Vector3d q = closest_point_on_triangle(triangles_[i], p);
    const double d = (q - p).norm();
    if (d >= shortest) continue;
    shortest = d;
    if (nearest) *nearest = q;
    if (normal) *normal = triangle_normal(triangles_[i]);
  }
  return shortest;
}

// Steps of half a cell along the segment, each with the cells within a quarter cell of it:
// every point of the segment lies within a quarter cell of a step, so every crossed triangle is
// listed.
bool WorldMesh::line_of_sight(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                              double margin_m) const {
  const Eigen::Vector3d delta = to - from;
  const double length = delta.norm();
  if (length <= 2.0 * margin_m) return true;
  const double margin = margin_m / length;
  const int steps = static_cast<int>(std::ceil(length / (0.5 * cell_m_)));
  const Eigen::Vector3d half = Eigen::Vector3d::Constant(0.25 * cell_m_ + 1e-9);
  for (int k = 0; k <= steps; ++k) {
    const Eigen::Vector3d at = from + delta * (static_cast<double>(k) / steps);
    for (uint32_t i : triangles_in(at - half, at + half)) {
      const double crossing = segment_crossing(triangles_[i], from, delta);
      if (crossing > margin && crossing < 1.0 - margin) return false;
    }
  }
  return true;
}

}  // namespace covox_rostest

#include "covoxslam/map/mesh_colors.h"

#include <algorithm>
#include <cmath>

namespace covox::map {

namespace {

// The colour map's anchors at 0, 1/4, 1/2, 3/4 and 1 of the range. Two neighbours share a channel
// that is at least 200 at both (blue-cyan: blue; cyan-green and green-yellow: green; yellow-red:
// red), so it stays at least 200 between them too: no height is shown dark.
constexpr int kAnchors = 5;
constexpr float kAnchorColors[kAnchors][3] = {{48.0f, 72.0f, 210.0f},   // blue
                                              {40.0f, 200.0f, 230.0f},  // cyan
                                              {70.0f, 215.0f, 90.0f},   // green
                                              {240.0f, 215.0f, 50.0f},  // yellow
                                              {225.0f, 70.0f, 50.0f}};  // red

uint8_t channel(float value) {
  return static_cast<uint8_t>(std::lround(std::clamp(value, 0.0f, 255.0f)));
}

}  // namespace

Rgb8 height_color(float height_m, const HeightColorRange& range) {
  const float width_m = range.max_height_m - range.min_height_m;
  float t = 0.5f;
  if (std::isfinite(height_m) && std::isfinite(width_m) && width_m > 0.0f)
    t = std::clamp((height_m - range.min_height_m) / width_m, 0.0f, 1.0f);
  const float position = t * (kAnchors - 1);
  const int lower = std::min(static_cast<int>(position), kAnchors - 2);
  const float f = position - static_cast<float>(lower);
  const float* a = kAnchorColors[lower];
  const float* b = kAnchorColors[lower + 1];
  return Rgb8{channel(a[0] + f * (b[0] - a[0])), channel(a[1] + f * (b[1] - a[1])),
              channel(a[2] + f * (b[2] - a[2]))};
}

bool has_observed_colors(const Mesh& mesh) {
  if (mesh.colors.size() != mesh.vertices_m.size()) return false;
  for (const Rgb8& color : mesh.colors) {
    if (!is_unobserved_color(color)) return true;
  }
  return false;
}

std::vector<Rgb8> display_colors(const Mesh& mesh, const Eigen::Isometry3d& T_world_mesh,
                                 const HeightColorRange& range) {
  const bool colored = mesh.colors.size() == mesh.vertices_m.size();
  // World z of a vertex: the third row of the transform applied to it.
  const Eigen::Vector3d z_row = T_world_mesh.linear().row(2).transpose();
  const double z_offset_m = T_world_mesh.translation().z();
  std::vector<Rgb8> colors(mesh.vertices_m.size());
  for (size_t v = 0; v < mesh.vertices_m.size(); ++v) {
    if (colored && !is_unobserved_color(mesh.colors[v])) {
      colors[v] = mesh.colors[v];
      continue;
    }
    const Vec3f& p = mesh.vertices_m[v];
    const double z_m = z_row.x() * p.x + z_row.y() * p.y + z_row.z() * p.z + z_offset_m;
    colors[v] = height_color(static_cast<float>(z_m), range);
  }
  return colors;
}

std::vector<Rgb8> shaded_face_colors(const Mesh& mesh, const Eigen::Isometry3d& T_world_mesh,
                                     const HeightColorRange& range) {
  const Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.5, 0.8).normalized();
  std::vector<Rgb8> colors;
  colors.reserve(mesh.triangle_count());
  for (size_t t = 0; t + 2 < mesh.triangles.size(); t += 3) {
    Eigen::Vector3d corners[3];
    int valid = 0;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c) {
      const uint32_t index = mesh.triangles[t + c];
      if (index >= mesh.vertices_m.size()) continue;
      const Vec3f& v = mesh.vertices_m[index];
      corners[valid] = T_world_mesh * Eigen::Vector3d(v.x, v.y, v.z);
      centre += corners[valid++];
    }
    if (valid == 0) {
      colors.push_back(height_color(std::nanf(""), range));
      continue;
    }
    centre /= valid;
    const Rgb8 base = height_color(static_cast<float>(centre.z()), range);
    const Eigen::Vector3d normal = valid == 3
                                       ? (corners[1] - corners[0]).cross(corners[2] - corners[0])
                                       : Eigen::Vector3d::Zero();
    const double length = normal.norm();
    const double shade = length > 0.0 && std::isfinite(length)
                             ? 0.55 + 0.45 * std::abs(normal.dot(light)) / length
                             : 1.0;
    auto scaled = [shade](uint8_t value) {
      return static_cast<uint8_t>(std::lround(std::min(255.0, value * shade)));
    };
    colors.push_back(Rgb8{scaled(base.r), scaled(base.g), scaled(base.b)});
  }
  return colors;
}

HeightColorRange vertex_height_range(const Mesh& mesh) {
  bool any = false;
  HeightColorRange range{0.0f, 0.0f};
  for (const Vec3f& v : mesh.vertices_m) {
    if (!std::isfinite(v.z)) continue;
    range.min_height_m = any ? std::min(range.min_height_m, v.z) : v.z;
    range.max_height_m = any ? std::max(range.max_height_m, v.z) : v.z;
    any = true;
  }
  return range;
}

}  // namespace covox::map

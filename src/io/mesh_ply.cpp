#include "covoxslam/io/mesh_ply.h"

#include <ostream>

#include "covoxslam/io/file_bytes.h"
#include "covoxslam/map/mesh_colors.h"

namespace covox {
namespace io {

void write_mesh_ply(std::ostream& file, const map::Mesh& mesh) {
  const bool has_color = mesh.colors.size() == mesh.vertices_m.size();
  // Vertices without a fused colour (black) are written in their height's colour, spread over
  // the mesh's own heights.
  const std::vector<Rgb8> colors =
      has_color
          ? map::display_colors(mesh, Eigen::Isometry3d::Identity(), map::vertex_height_range(mesh))
          : std::vector<Rgb8>();
  file << "ply\nformat binary_little_endian 1.0\ncomment written by covoxslam\n"
       << "element vertex " << mesh.vertices_m.size() << "\n"
       << "property float x\nproperty float y\nproperty float z\n";
  if (has_color) file << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  file << "element face " << mesh.triangle_count() << "\n"
       << "property list uchar int vertex_indices\nend_header\n";
  for (size_t v = 0; v < mesh.vertices_m.size(); ++v) {
    const float xyz[3] = {mesh.vertices_m[v].x, mesh.vertices_m[v].y, mesh.vertices_m[v].z};
    file.write(reinterpret_cast<const char*>(xyz), sizeof(xyz));
    if (has_color) {
      const unsigned char rgb[3] = {colors[v].r, colors[v].g, colors[v].b};
      file.write(reinterpret_cast<const char*>(rgb), sizeof(rgb));
    }
  }
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    const unsigned char three = 3;
    const int32_t indices[3] = {static_cast<int32_t>(mesh.triangles[3 * t]),
                                static_cast<int32_t>(mesh.triangles[3 * t + 1]),
                                static_cast<int32_t>(mesh.triangles[3 * t + 2])};
    file.write(reinterpret_cast<const char*>(&three), 1);
    file.write(reinterpret_cast<const char*>(indices), sizeof(indices));
  }
}

void write_mesh_ply(const std::string& path, const map::Mesh& mesh) {
  write_file_replacing(path, "write_mesh_ply", /*binary=*/true,
                       [&](std::ostream& file) { write_mesh_ply(file, mesh); });
}

}  // namespace io
}  // namespace covox

#pragma once
// Display colours of a mesh, shared by the PLY writer and the ROS mesh markers, so that a mesh is
// never black. A vertex keeps its fused colour (camera colour, or intensity fused as grey) unless
// that colour is exactly black: the colour layer's empty value, which is what every vertex holds
// when the sensor gave neither colour nor intensity (or integrate_color was off). Such a vertex is
// coloured by its height instead, on a fixed colour map whose darkest entry is still bright.
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/vec3.h"
#include "covoxslam/map/mesh.h"

namespace covox::map {

// The heights mapped to the two ends of the colour map; heights outside are clamped to the ends.
struct HeightColorRange {
  float min_height_m = 0.0f;
  float max_height_m = 10.0f;
};

// Blue (min) through cyan, green and yellow to red (max), linear between those five anchors. A
// range of zero width (or a non-finite height) gives the middle of the map.
Rgb8 height_color(float height_m, const HeightColorRange& range);

// True when `color` holds no fused observation (exactly black).
inline bool is_unobserved_color(const Rgb8& color) {
  return color.r == 0 && color.g == 0 && color.b == 0;
}

// True when at least one vertex carries a fused colour.
bool has_observed_colors(const Mesh& mesh);

// One colour per vertex: the vertex's own colour when observed, otherwise the height colour of
// its world height (T_world_mesh * vertex).z. A mesh without colours gets height colours only.
std::vector<Rgb8> display_colors(const Mesh& mesh, const Eigen::Isometry3d& T_world_mesh,
                                 const HeightColorRange& range);

// One colour per triangle (mesh.triangles in threes) for a mesh without fused colours, lit the same
// from both sides: the height colour of the triangle's world centre, scaled by a shade of
// 0.55 + 0.45 |n . l| for its world normal n and a fixed light l from above and aside. Viewers
// that light one side only (rviz's triangle lists leave a face seen from behind unlit, black)
// draw such a colour unlit, so either side shows the same shaded colour. A degenerate triangle (or
// one with an index past the vertices) gets the unshaded height colour of its valid corners, or
// the map's middle colour.
std::vector<Rgb8> shaded_face_colors(const Mesh& mesh, const Eigen::Isometry3d& T_world_mesh,
                                     const HeightColorRange& range);

// The lowest and highest finite vertex of `mesh` as a range (0 to 0 without one): the PLY writer
// spreads a whole map's heights over the colour map with it.
HeightColorRange vertex_height_range(const Mesh& mesh);

}  // namespace covox::map

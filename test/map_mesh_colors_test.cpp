// Mesh display colours (map/mesh_colors.h): the height colour map is never dark and follows the
// world height, fused colours are kept, black (unobserved) vertices are coloured by height, and
// the PLY writer writes exactly those colours; face colours are shaded alike from both sides.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/ply_reader.h"
#include "covoxslam/map/mesh_colors.h"

namespace covox {
namespace {

int brightest_channel(const Rgb8& c) { return std::max({int(c.r), int(c.g), int(c.b)}); }

bool same(const Rgb8& a, const Rgb8& b) { return a.r == b.r && a.g == b.g && a.b == b.b; }

TEST(MeshColors, HeightColorMapIsNeverDarkAndClampsOutsideItsRange) {
  const map::HeightColorRange range{-2.0f, 8.0f};
  for (int i = -50; i <= 150; ++i) {
    const Rgb8 c = map::height_color(-2.0f + 0.1f * i, range);
    EXPECT_GE(brightest_channel(c), 200) << "height " << -2.0f + 0.1f * i;
  }
  // Below the range is the low end (blue dominates), above it the high end (red dominates).
  const Rgb8 low = map::height_color(-100.0f, range), high = map::height_color(100.0f, range);
  EXPECT_TRUE(same(low, map::height_color(-2.0f, range)));
  EXPECT_TRUE(same(high, map::height_color(8.0f, range)));
  EXPECT_GT(low.b, low.r);
  EXPECT_GT(high.r, high.b);
  // Neighbouring heights get neighbouring colours (linear pieces: at most a few levels per cm).
  for (int i = 0; i < 1000; ++i) {
    const Rgb8 a = map::height_color(-2.0f + 0.01f * i, range);
    const Rgb8 b = map::height_color(-2.0f + 0.01f * (i + 1), range);
    EXPECT_LE(std::abs(int(a.r) - int(b.r)) + std::abs(int(a.g) - int(b.g)) +
                  std::abs(int(a.b) - int(b.b)),
              6)
        << i;
  }
  // Degenerate input still gives a bright colour.
  EXPECT_GE(brightest_channel(map::height_color(NAN, range)), 200);
  EXPECT_GE(brightest_channel(map::height_color(1.0f, map::HeightColorRange{3.0f, 3.0f})), 200);
}

// Three vertices at heights 0, 1 and 2 m in the mesh frame; the middle one has a fused colour.
map::Mesh three_vertex_mesh() {
  map::Mesh mesh;
  mesh.vertices_m = {Vec3f(0.0f, 0.0f, 0.0f), Vec3f(1.0f, 0.0f, 1.0f), Vec3f(0.0f, 1.0f, 2.0f)};
  mesh.colors = {Rgb8{0, 0, 0}, Rgb8{10, 20, 30}, Rgb8{0, 0, 0}};
  mesh.triangles = {0, 1, 2};
  return mesh;
}

TEST(MeshColors, BlackVerticesTakeTheColourOfTheirWorldHeight) {
  const map::Mesh mesh = three_vertex_mesh();
  const map::HeightColorRange range{0.0f, 10.0f};
  // The mesh frame sits 4 m up, turned about z (which keeps heights).
  Eigen::Isometry3d T_world_mesh = Eigen::Isometry3d::Identity();
  T_world_mesh.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T_world_mesh.translation() = Eigen::Vector3d(5.0, -3.0, 4.0);
  const std::vector<Rgb8> colors = map::display_colors(mesh, T_world_mesh, range);
  ASSERT_EQ(colors.size(), 3u);
  EXPECT_TRUE(same(colors[0], map::height_color(4.0f, range)));
  EXPECT_TRUE(same(colors[1], mesh.colors[1]));  // fused colour kept, however dark
  EXPECT_TRUE(same(colors[2], map::height_color(6.0f, range)));
  EXPECT_FALSE(same(colors[0], colors[2]));
  // A pitched frame: the world height mixes the vertex's x and z.
  Eigen::Isometry3d pitched = Eigen::Isometry3d::Identity();
  pitched.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  // Rotating (1, 0, 1) by +90 degrees about y gives (1, 0, -1).
  EXPECT_TRUE(same(map::display_colors(mesh, pitched, map::HeightColorRange{-1.0f, 1.0f})[0],
                   map::height_color(0.0f, map::HeightColorRange{-1.0f, 1.0f})));
  map::Mesh uncolored = mesh;
  uncolored.colors.clear();
  const std::vector<Rgb8> by_height = map::display_colors(uncolored, T_world_mesh, range);
  EXPECT_TRUE(same(by_height[1], map::height_color(5.0f, range)));
}

// A flat roof and a wall, each in both windings (seen from above / outside, or from below /
// inside): one colour per triangle, the same for either winding, never dark; the roof faces the
// light more squarely than the wall, so it is brighter; the hue is the centre's height colour.
TEST(MeshColors, FaceColoursAreShadedAlikeFromBothSidesAndNeverDark) {
  map::Mesh mesh;
  mesh.vertices_m = {Vec3f(0, 0, 3), Vec3f(1, 0, 3), Vec3f(0, 1, 3),   // roof at 3 m
                     Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 0, 3)};  // wall in the x-z plane
  mesh.triangles = {0, 1, 2, 0, 2, 1, 3, 4, 5, 3, 5, 4, 0, 1, 9};      // the last: a bad index
  const map::HeightColorRange range{0.0f, 10.0f};
  const std::vector<Rgb8> colors =
      map::shaded_face_colors(mesh, Eigen::Isometry3d::Identity(), range);
  ASSERT_EQ(colors.size(), 5u);
  EXPECT_TRUE(same(colors[0], colors[1]));
  EXPECT_TRUE(same(colors[2], colors[3]));
  for (const Rgb8& color : colors) EXPECT_GE(brightest_channel(color), 100);
  EXPECT_GT(brightest_channel(colors[0]), brightest_channel(colors[2]));
  // Shading scales every channel of the centre's height colour alike.
  const Rgb8 roof_height = map::height_color(3.0f, range);
  const double shade = colors[0].g / double(roof_height.g);
  EXPECT_GT(shade, 0.5);
  EXPECT_LE(shade, 1.0);
  EXPECT_NEAR(colors[0].r, shade * roof_height.r, 1.0);
  EXPECT_NEAR(colors[0].b, shade * roof_height.b, 1.0);
  // The bad triangle keeps the unshaded colour of its two valid corners' centre (3 m).
  EXPECT_TRUE(same(colors[4], roof_height));
}

TEST(MeshColors, PlyWriterColoursBlackVerticesByTheMeshHeights) {
  const map::Mesh mesh = three_vertex_mesh();
  const std::string path = ::testing::TempDir() + "/covox_mesh_colors.ply";
  io::write_mesh_ply(path, mesh);
  const map::Mesh read = io::read_mesh_ply(path);
  ASSERT_EQ(read.colors.size(), 3u);
  const map::HeightColorRange range = map::vertex_height_range(mesh);
  EXPECT_FLOAT_EQ(range.min_height_m, 0.0f);
  EXPECT_FLOAT_EQ(range.max_height_m, 2.0f);
  EXPECT_TRUE(same(read.colors[0], map::height_color(0.0f, range)));
  EXPECT_TRUE(same(read.colors[1], mesh.colors[1]));
  EXPECT_TRUE(same(read.colors[2], map::height_color(2.0f, range)));
  for (const Rgb8& c : read.colors) EXPECT_FALSE(map::is_unobserved_color(c));
}

}  // namespace
}  // namespace covox

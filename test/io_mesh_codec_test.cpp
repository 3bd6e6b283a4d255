// The compact mesh codec: every decoded vertex within half a step of the encoded one, indices and
// colours exact, and every malformed input refused with an error rather than a crash.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/io/mesh_codec.h"

namespace covox {
namespace {

// Vertices scattered over a 200 m cube (near and far from the origin, both signs), triangles
// with indices in any order, optionally one colour per vertex.
map::Mesh random_mesh(int vertices, int triangles, bool colored, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coordinate(-100.0f, 100.0f);
  std::uniform_int_distribution<uint32_t> index(0, static_cast<uint32_t>(vertices - 1));
  std::uniform_int_distribution<int> byte(0, 255);
  map::Mesh mesh;
  for (int k = 0; k < vertices; ++k) {
    mesh.vertices_m.emplace_back(coordinate(rng), coordinate(rng), coordinate(rng));
    if (colored)
      mesh.colors.push_back(Rgb8{static_cast<uint8_t>(byte(rng)), static_cast<uint8_t>(byte(rng)),
                                 static_cast<uint8_t>(byte(rng))});
  }
  for (int k = 0; k < 3 * triangles; ++k) mesh.triangles.push_back(index(rng));
  return mesh;
}

void expect_within_half_a_step(const map::Mesh& decoded, const map::Mesh& original, float step_m) {
  ASSERT_EQ(decoded.vertices_m.size(), original.vertices_m.size());
  double worst_m = 0.0;
  for (size_t k = 0; k < original.vertices_m.size(); ++k) {
    const Vec3f& a = decoded.vertices_m[k];
    const Vec3f& b = original.vertices_m[k];
    worst_m = std::max({worst_m, std::fabs(double(a.x) - b.x), std::fabs(double(a.y) - b.y),
                        std::fabs(double(a.z) - b.z)});
  }
  // Half a step plus the float rounding of a decoded coordinate of up to 100 m.
  EXPECT_LE(worst_m, 0.5 * step_m + 100.0 * std::ldexp(1.0, -23));
  EXPECT_EQ(decoded.triangles, original.triangles);
  ASSERT_EQ(decoded.colors.size(), original.colors.size());
  for (size_t k = 0; k < original.colors.size(); ++k) {
    EXPECT_EQ(decoded.colors[k].r, original.colors[k].r);
    EXPECT_EQ(decoded.colors[k].g, original.colors[k].g);
    EXPECT_EQ(decoded.colors[k].b, original.colors[k].b);
  }
}

TEST(MeshCodec, DecodedVerticesLieWithinHalfAStepAndIndicesAndColoursAreExact) {
  for (const bool colored : {false, true}) {
    for (const float step_m : {0.2f / 256.0f, 0.01f, 0.7f}) {
      const map::Mesh mesh = random_mesh(500, 900, colored, colored ? 3 : 4);
      const std::vector<uint8_t> bytes = io::encode_mesh(mesh, step_m);
      expect_within_half_a_step(io::decode_mesh(bytes, "test"), mesh, step_m);
    }
  }
  const map::Mesh empty;
  EXPECT_TRUE(io::decode_mesh(io::encode_mesh(empty, 0.01f), "test").empty());
}

TEST(MeshCodec, RefusesWhatItCannotEncode) {
  map::Mesh mesh = random_mesh(10, 5, true, 5);
  EXPECT_THROW(io::encode_mesh(mesh, 0.0f), Error);
  EXPECT_THROW(io::encode_mesh(mesh, std::nanf("")), Error);
  map::Mesh short_colors = mesh;
  short_colors.colors.pop_back();
  EXPECT_THROW(io::encode_mesh(short_colors, 0.01f), Error);
  map::Mesh bad_index = mesh;
  bad_index.triangles[4] = 10;
  EXPECT_THROW(io::encode_mesh(bad_index, 0.01f), Error);
  map::Mesh far = mesh;
  far.vertices_m[3].y = 1e30f;
  EXPECT_THROW(io::encode_mesh(far, 1e-6f), Error);
}

TEST(MeshCodec, RefusesTruncatedLongerOrAlteredBytes) {
  const std::vector<uint8_t> good = io::encode_mesh(random_mesh(40, 60, true, 6), 0.001f);
  ASSERT_NO_THROW(io::decode_mesh(good, "test"));
  for (size_t size = 0; size < good.size(); ++size)
    EXPECT_THROW(io::decode_mesh(good.data(), size, "test"), Error) << size;
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_THROW(io::decode_mesh(longer, "test"), Error);
  std::vector<uint8_t> magic = good;
  magic[3] = 'S';
  EXPECT_THROW(io::decode_mesh(magic, "test"), Error);
  std::vector<uint8_t> version = good;
  version[4] = 9;
  EXPECT_THROW(io::decode_mesh(version, "test"), Error);
  std::vector<uint8_t> count = good;
  count[16] = 0xff;  // the vertex count's fifth byte: more vertices than bytes
  EXPECT_THROW(io::decode_mesh(count, "test"), Error);
  // The last index's difference pushed past the last vertex.
  std::vector<uint8_t> index = good;
  index.back() = 0x7e;
  EXPECT_THROW(io::decode_mesh(index, "test"), Error);
}

}  // namespace
}  // namespace covox

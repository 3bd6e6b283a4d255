// Ray pieces (tsdf_kernels.h): cutting a ray into pieces walked by separate threads must visit
// the same number of voxels as the whole ray, each once, as one 6-connected path from the ray's
// first voxel to its last - for any ray, including long, axis-aligned, tiny and far-from-origin
// ones where float rounding near the cuts is most likely to bite. The CPU twin's one-pass piece
// table must give the same cuts and counts as the per-piece functions the GPU uses.
#include <gtest/gtest.h>

#include <random>
#include <set>
#include <tuple>
#include <vector>

#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox {
namespace {

using integrators::tsdf::RaySegment;

std::vector<Index3D> walk_in_pieces(const RaySegment& ray, float inverse_voxel_size) {
  const uint32_t pieces = integrators::tsdf::ray_piece_count(
      integrators::tsdf::ray_voxel_count(ray, inverse_voxel_size));
  std::vector<Index3D> voxels;
  for (uint32_t k = 0; k < pieces; ++k) {
    const size_t before = voxels.size();
    integrators::tsdf::traverse_ray_piece(ray, k, pieces, inverse_voxel_size,
                                          [&](const Index3D& v) { voxels.push_back(v); });
    EXPECT_EQ(voxels.size() - before,
              integrators::tsdf::ray_piece_voxel_count(ray, k, pieces, inverse_voxel_size))
        << "piece " << k;
  }
  return voxels;
}

void expect_valid_walk(const RaySegment& ray, float voxel_size) {
  const float inverse = 1.0f / voxel_size;
  const std::vector<Index3D> voxels = walk_in_pieces(ray, inverse);
  ASSERT_EQ(voxels.size(), integrators::tsdf::ray_voxel_count(ray, inverse));
  ASSERT_FALSE(voxels.empty());
  EXPECT_EQ(voxels.front(), integrators::tsdf::voxel_of(ray.start, inverse));
  EXPECT_EQ(voxels.back(), integrators::tsdf::voxel_of(ray.end, inverse));
  std::set<std::tuple<int, int, int>> distinct;
  for (size_t i = 0; i < voxels.size(); ++i) {
    distinct.insert({voxels[i].x, voxels[i].y, voxels[i].z});
    if (i > 0) {
      const Index3D d = voxels[i] - voxels[i - 1];
      EXPECT_EQ(integrators::tsdf::abs_i32(d.x) + integrators::tsdf::abs_i32(d.y) +
                    integrators::tsdf::abs_i32(d.z),
                1)
          << "step " << i;
    }
  }
  EXPECT_EQ(distinct.size(), voxels.size()) << "a voxel was visited twice";
  // One thread per whole ray visits the same number of voxels (the path may differ only where
  // rounding at a cut picks the other of two equally valid neighbours).
  size_t whole = 0;
  integrators::tsdf::traverse_ray(ray, inverse, [&](const Index3D&) { ++whole; });
  EXPECT_EQ(whole, voxels.size());
  // The CPU twin's piece table (cuts computed once, in order) has the cuts and counts that the
  // GPU computes piece by piece.
  const uint32_t pieces =
      integrators::tsdf::ray_piece_count(integrators::tsdf::ray_voxel_count(ray, inverse));
  uint32_t listed = 0;
  integrators::tsdf::for_each_ray_piece(
      ray, pieces, inverse, [&](uint32_t k, const Index3D& first, uint32_t count) {
        EXPECT_EQ(k, listed++);
        EXPECT_EQ(first, integrators::tsdf::ray_cut_voxel(ray, k, pieces, inverse))
            << "piece " << k;
        EXPECT_EQ(count, integrators::tsdf::ray_piece_voxel_count(ray, k, pieces, inverse))
            << "piece " << k;
      });
  EXPECT_EQ(listed, pieces);
}

RaySegment segment(const Vec3f& start, const Vec3f& end) {
  RaySegment ray;
  ray.start = start;
  ray.end = end;
  ray.kind = integrators::tsdf::kSurfaceRay;
  return ray;
}

TEST(TsdfRayPieces, RandomRaysVisitEveryVoxelOnceAsOnePath) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  for (float voxel_size : {0.02f, 0.05f, 0.2f}) {
    for (float offset : {0.0f, 137.3f, -4096.7f}) {
      for (int r = 0; r < 300; ++r) {
        const Vec3f start(offset + 3.0f * unit(rng), offset + 3.0f * unit(rng), 2.0f * unit(rng));
        const float length = 0.01f + 20.0f * (0.5f + 0.5f * unit(rng));
        Vec3f direction(unit(rng), unit(rng), unit(rng));
        if (direction.norm() < 1e-3f) direction = Vec3f(1.0f, 0.0f, 0.0f);
        direction = direction * (1.0f / direction.norm());
        expect_valid_walk(segment(start, start + direction * length), voxel_size);
      }
    }
  }
}

TEST(TsdfRayPieces, AxisAlignedDiagonalAndTinyRays) {
  expect_valid_walk(segment(Vec3f(0.01f, 0.01f, 0.01f), Vec3f(9.99f, 0.01f, 0.01f)),
                    0.1f);  // along x
  expect_valid_walk(segment(Vec3f(0.05f, 0.05f, 0.05f), Vec3f(-7.95f, -7.95f, 0.05f)),
                    0.1f);  // exact diagonal
  expect_valid_walk(segment(Vec3f(0.0f, 0.0f, 0.0f), Vec3f(4.0f, 4.0f, 4.0f)),
                    0.2f);  // through corners
  expect_valid_walk(segment(Vec3f(1.234f, 2.345f, 3.456f), Vec3f(1.2341f, 2.3451f, 3.4561f)),
                    0.05f);  // one voxel
  expect_valid_walk(segment(Vec3f(0.0f, 0.0f, 0.0f), Vec3f(0.0f, 0.0f, 50.0f)),
                    0.02f);  // 2500 voxels up z
}

}  // namespace
}  // namespace covox

// Frame key codec (tsdf_kernels.h): a coloured frame's reduction recovers each record's voxel
// from its key (FrameKeyCodec::voxel, shifts and 32-bit division for short keys), so voxel(key)
// must invert key() for every voxel of the box, at both block sizes, for boxes with 32-bit keys
// and for boxes that need 64-bit keys; voxels outside the box must get the out-of-range key.
#include <gtest/gtest.h>

#include <random>

#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox {
namespace {

void expect_round_trip(const Index3D& low, const Index3D& high, int32_t voxels_per_side,
                       int samples) {
  const integrators::tsdf::FrameKeyCodec codec =
      integrators::tsdf::make_frame_key_codec(low, high, voxels_per_side);
  std::mt19937 random(7);
  std::uniform_int_distribution<int32_t> x(low.x, high.x), y(low.y, high.y), z(low.z, high.z);
  for (int i = 0; i < samples; ++i) {
    // The box's corners first (the extreme blocks and voxels within them), then random voxels.
    const Index3D voxel =
        i < 8 ? Index3D(i & 1 ? high.x : low.x, i & 2 ? high.y : low.y, i & 4 ? high.z : low.z)
              : Index3D(x(random), y(random), z(random));
    const uint64_t key = codec.key(voxel);
    ASSERT_LT(key, codec.out_of_range_key) << voxel.x << " " << voxel.y << " " << voxel.z;
    const Index3D back = codec.voxel(key);
    ASSERT_EQ(back.x, voxel.x);
    ASSERT_EQ(back.y, voxel.y);
    ASSERT_EQ(back.z, voxel.z);
  }
  // The codec pads the box by one block per side; two blocks out is outside.
  const int32_t out = 2 * voxels_per_side + 1;
  EXPECT_EQ(codec.key(Index3D(low.x - out, low.y, low.z)), codec.out_of_range_key);
  EXPECT_EQ(codec.key(Index3D(low.x, low.y, high.z + out)), codec.out_of_range_key);
}

TEST(TsdfFrameKeyCodec, VoxelInvertsKeyForShortKeys) {
  for (const int32_t side : {8, 16}) {
    SCOPED_TRACE(side);
    const Index3D low(-81, -80, -25),
        high(80, 83, 22);  // a 16 m LiDAR frame at 0.2 m, around the origin
    ASSERT_LE(integrators::tsdf::make_frame_key_codec(low, high, side).key_bits, 32);
    expect_round_trip(low, high, side, 20000);
  }
}

TEST(TsdfFrameKeyCodec, VoxelInvertsKeyForLongKeys) {
  for (const int32_t side : {8, 16}) {
    SCOPED_TRACE(side);
    const Index3D low(-20000, 5000, -3000),
        high(26000, 61000, 2500);  // far from the origin, hundreds of metres
    ASSERT_GT(integrators::tsdf::make_frame_key_codec(low, high, side).key_bits, 32);
    expect_round_trip(low, high, side, 20000);
  }
}

}  // namespace
}  // namespace covox

// Tile order of a depth image's points (tsdf::pixel_tile_order, tsdf_kernels.h): every pixel
// gets its own place in [0, width x height), for image sizes that are and are not multiples of
// the tile, and each full tile's 32 pixels are consecutive; pixel_at_tile_place (which the merge
// uses to read a depth image in place) inverts it.
#include <gtest/gtest.h>

#include <vector>

#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox {
namespace {

TEST(TsdfPixelOrder, EveryPixelGetsItsOwnPlace) {
  for (const auto& size :
       std::vector<std::pair<int, int>>{{640, 480}, {13, 7}, {1, 1}, {9, 5}, {8, 4}, {3, 11}}) {
    const int width = size.first, height = size.second;
    std::vector<int> hits(static_cast<size_t>(width) * height, 0);
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const int64_t place = integrators::tsdf::pixel_tile_order(u, v, width, height);
        ASSERT_GE(place, 0) << width << "x" << height << " pixel " << u << "," << v;
        ASSERT_LT(place, static_cast<int64_t>(hits.size()))
            << width << "x" << height << " pixel " << u << "," << v;
        ++hits[static_cast<size_t>(place)];
      }
    }
    for (size_t k = 0; k < hits.size(); ++k)
      ASSERT_EQ(hits[k], 1) << width << "x" << height << " place " << k;
  }
}

TEST(TsdfPixelOrder, EveryPlaceLeadsBackToItsPixel) {
  for (const auto& size : std::vector<std::pair<int, int>>{
           {640, 480}, {13, 7}, {1, 1}, {9, 5}, {8, 4}, {3, 11}, {157, 117}}) {
    const int width = size.first, height = size.second;
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const int64_t place = integrators::tsdf::pixel_tile_order(u, v, width, height);
        ASSERT_EQ(integrators::tsdf::pixel_at_tile_place(place, width, height),
                  static_cast<int64_t>(v) * width + u)
            << width << "x" << height << " pixel " << u << "," << v << " place " << place;
      }
    }
  }
}

TEST(TsdfPixelOrder, AFullTileIsOneRunOfThirtyTwo) {
  const int width = 640, height = 480;
  // The tile of pixels (16..23, 8..11): band 2, column 2.
  const int64_t first = integrators::tsdf::pixel_tile_order(16, 8, width, height);
  EXPECT_EQ(first, 2 * 4 * width + 2 * 8 * 4);
  for (int v = 8; v < 12; ++v) {
    for (int u = 16; u < 24; ++u) {
      EXPECT_EQ(integrators::tsdf::pixel_tile_order(u, v, width, height),
                first + (v - 8) * 8 + (u - 16));
    }
  }
}

}  // namespace
}  // namespace covox

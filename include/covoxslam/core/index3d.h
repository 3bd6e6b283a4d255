#pragma once
#include <cstdint>

#include "covoxslam/core/macros.h"

namespace covox {

// An integer 3-D index: a block index in a layer, or a voxel index inside a block / the grid.
struct Index3D {
  int32_t x = 0;
  int32_t y = 0;
  int32_t z = 0;

  constexpr Index3D() = default;
  COVOX_HD constexpr Index3D(int32_t x_in, int32_t y_in, int32_t z_in)
      : x(x_in), y(y_in), z(z_in) {}

  COVOX_HD constexpr Index3D operator+(const Index3D& o) const {
    return {x + o.x, y + o.y, z + o.z};
  }
  COVOX_HD constexpr Index3D operator-(const Index3D& o) const {
    return {x - o.x, y - o.y, z - o.z};
  }
  COVOX_HD constexpr bool operator==(const Index3D& o) const {
    return x == o.x && y == o.y && z == o.z;
  }
  COVOX_HD constexpr bool operator!=(const Index3D& o) const { return !(*this == o); }
  // Lexicographic (x, then y, then z): lets indices be sorted and used in std::map.
  COVOX_HD constexpr bool operator<(const Index3D& o) const {
    return x != o.x ? x < o.x : (y != o.y ? y < o.y : z < o.z);
  }
};

// Floor division that is correct for negative numerators (C++ '/' truncates toward zero):
// the block holding voxel -1 along an axis is block -1, not block 0.
COVOX_HD_INLINE int32_t floor_divide(int32_t numerator, int32_t denominator) {
  const int32_t quotient = numerator / denominator;
  return (numerator % denominator != 0 && ((numerator < 0) != (denominator < 0))) ? quotient - 1
                                                                                  : quotient;
}

}  // namespace covox

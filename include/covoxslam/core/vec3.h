#pragma once
// Small fixed-size math usable in kernels on both backends (Eigen stays on the host side).
#include <cmath>
#include <cstdint>

#include "covoxslam/core/macros.h"

namespace covox {

struct Vec3f {
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;

  constexpr Vec3f() = default;
  COVOX_HD constexpr Vec3f(float x_in, float y_in, float z_in) : x(x_in), y(y_in), z(z_in) {}

  COVOX_HD_INLINE Vec3f operator+(const Vec3f& o) const { return {x + o.x, y + o.y, z + o.z}; }
  COVOX_HD_INLINE Vec3f operator-(const Vec3f& o) const { return {x - o.x, y - o.y, z - o.z}; }
  COVOX_HD_INLINE Vec3f operator*(float s) const { return {x * s, y * s, z * s}; }
  COVOX_HD_INLINE float dot(const Vec3f& o) const { return x * o.x + y * o.y + z * o.z; }
  COVOX_HD_INLINE float norm() const { return sqrtf(dot(*this)); }
  COVOX_HD_INLINE float operator[](int axis) const { return axis == 0 ? x : (axis == 1 ? y : z); }
  COVOX_HD_INLINE bool is_finite() const {
#if COVOX_DEVICE_CODE
    return isfinite(x) && isfinite(y) && isfinite(z);
#else
    return std::isfinite(x) && std::isfinite(y) && std::isfinite(z);
#endif
  }
};

// A rigid transform (rotation matrix, row-major, and translation): p' = R p + t.
struct Transform3f {
  float rotation[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  Vec3f translation;

  COVOX_HD_INLINE Vec3f rotate(const Vec3f& p) const {
    return {rotation[0] * p.x + rotation[1] * p.y + rotation[2] * p.z,
            rotation[3] * p.x + rotation[4] * p.y + rotation[5] * p.z,
            rotation[6] * p.x + rotation[7] * p.y + rotation[8] * p.z};
  }
  COVOX_HD_INLINE Vec3f operator*(const Vec3f& p) const { return rotate(p) + translation; }
};

struct Rgb8 {
  uint8_t r = 0;
  uint8_t g = 0;
  uint8_t b = 0;
};

}  // namespace covox

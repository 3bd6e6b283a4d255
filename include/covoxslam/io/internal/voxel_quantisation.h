#pragma once
// The quantisation of the submap codec (submap_codec.h) as one source for the host encoder and
// the kernels of both backends: a voxel encoded on the GPU gives the same bytes as on the host.
#include <cmath>
#include <cstdint>
#include <cstring>

#include "covoxslam/core/bit_count.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/map/voxels.h"

namespace covox::io::internal {

constexpr double kDistanceSteps = 32767.0;

// IEEE binary16 from a float: round to nearest even, finite values above 65504 saturate, NaN and
// infinities keep their class.
COVOX_HD_INLINE uint16_t float_to_half_bits(float value) {
  uint32_t bits;
  memcpy(&bits, &value, sizeof(bits));
  const uint32_t sign = (bits >> 16) & 0x8000u;
  const uint32_t float_exponent = (bits >> 23) & 0xffu;
  uint32_t mantissa = bits & 0x7fffffu;
  if (float_exponent == 0xffu)
    return static_cast<uint16_t>(sign | 0x7c00u | (mantissa ? 0x200u : 0u));
  const int exponent = static_cast<int>(float_exponent) - 127 + 15;
  if (exponent >= 31) return static_cast<uint16_t>(sign | 0x7bffu);
  if (exponent <= 0) {
    // Subnormal half: value = m * 2^-24, m = (1.mantissa << 23) >> (14 - exponent).
    if (exponent < -10) return static_cast<uint16_t>(sign);
    mantissa |= 0x800000u;
    const uint32_t shift = static_cast<uint32_t>(14 - exponent);
    uint32_t half = mantissa >> shift;
    const uint32_t remainder = mantissa & ((1u << shift) - 1u);
    const uint32_t halfway = 1u << (shift - 1u);
    if (remainder > halfway || (remainder == halfway && (half & 1u))) ++half;
    return static_cast<uint16_t>(sign | half);
  }
  uint32_t half = (static_cast<uint32_t>(exponent) << 10) | (mantissa >> 13);
  const uint32_t remainder = mantissa & 0x1fffu;
  // A carry out of the mantissa moves into the exponent, which is the right rounding.
  if (remainder > 0x1000u || (remainder == 0x1000u && (half & 1u))) ++half;
  if (half >= 0x7c00u) half = 0x7bffu;
  return static_cast<uint16_t>(sign | half);
}

// The float of IEEE binary16 bits (exact: every half is a float).
COVOX_HD_INLINE float half_bits_to_float(uint16_t half) {
  const uint32_t sign = static_cast<uint32_t>(half & 0x8000u) << 16;
  const uint32_t exponent = (half >> 10) & 0x1fu;
  const uint32_t mantissa = half & 0x3ffu;
  if (exponent == 0) {
    // Subnormal: mantissa * 2^-24, exact in a float.
    const float magnitude = static_cast<float>(mantissa) * 5.9604644775390625e-8f;
    return sign ? -magnitude : magnitude;
  }
  uint32_t bits = sign | (mantissa << 13);
  bits |= exponent == 31 ? 0x7f800000u : (exponent - 15 + 127) << 23;
  float value;
  memcpy(&value, &bits, sizeof(value));
  return value;
}

// int16 of clamp(distance / scale, -1, 1) * 32767, rounded half away from zero; NaN gives 0.
COVOX_HD_INLINE int16_t quantise_distance(float distance_m, double scale_m) {
  if (distance_m != distance_m) return 0;
  double unit = static_cast<double>(distance_m) / scale_m;
  unit = unit < -1.0 ? -1.0 : (unit > 1.0 ? 1.0 : unit);
  return static_cast<int16_t>(::round(unit * kDistanceSteps));
}

COVOX_HD_INLINE float dequantise_distance(int16_t distance, float scale_m) {
  return static_cast<float>(distance) * (scale_m / static_cast<float>(kDistanceSteps));
}

// The quantised fields of one voxel: all zero is the never-observed voxel.
struct QuantisedVoxel {
  int16_t distance = 0;
  uint16_t weight = 0;
  uint8_t r = 0, g = 0, b = 0;
  uint16_t color_weight = 0;
  COVOX_HD_INLINE bool has_color() const { return r != 0 || g != 0 || b != 0 || color_weight != 0; }
  COVOX_HD_INLINE bool observed() const { return distance != 0 || weight != 0 || has_color(); }
};

COVOX_HD_INLINE QuantisedVoxel quantise(const map::TsdfVoxel& tsdf, const map::ColorVoxel& color,
                                        double scale_m) {
  QuantisedVoxel q;
  q.distance = quantise_distance(tsdf.distance_m, scale_m);
  q.weight = float_to_half_bits(tsdf.weight);
  q.r = color.r;
  q.g = color.g;
  q.b = color.b;
  q.color_weight = float_to_half_bits(color.weight);
  return q;
}

// Little-endian 16-bit fields at any byte offset of the encoded bytes.
COVOX_HD_INLINE uint16_t load_u16(const uint8_t* at) {
  return static_cast<uint16_t>(at[0] | (static_cast<uint16_t>(at[1]) << 8));
}
COVOX_HD_INLINE void store_u16(uint8_t* at, uint16_t value) {
  at[0] = static_cast<uint8_t>(value & 0xffu);
  at[1] = static_cast<uint8_t>(value >> 8);
}

}  // namespace covox::io::internal

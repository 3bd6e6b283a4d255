#pragma once
// "Merged" integration (voxblox's MergedTsdfIntegrator, the paper's merged rays): points whose
// measured surface falls into the same voxel are bundled, and one ray is cast from their mean
// with their summed weight and mean colour. A depth camera puts hundreds of pixels into one
// 5 cm voxel and a LiDAR many returns into one 20 cm voxel near the sensor, so this removes most
// of the raycasting while changing the band only by how far the points of one voxel spread.
//
// The sums are integers (positions in 2^-30 m, colour channels, counts), so they are exact and
// independent of the order a backend reduces in: both backends and every run give bit-identical
// merged rays. A bundle of one point keeps the original point exactly.
#include <cstdint>

#include "covoxslam/core/macros.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/tsdf_kernels.h"

namespace covox {
namespace tsdf {

// 2^30 units per metre: every float coordinate of magnitude >= 2^-7 m is a whole number of units
// (its ulp is at least 2^-30), so the mean of identical points is the point itself; and 64-bit
// sums of 4 million points up to kMaxMergedRange_m away cannot overflow (2^22 * 2^10 * 2^30).
constexpr float kMergeUnitsPerMetre = 1073741824.0f;
constexpr float kMaxMergedRange_m = 1000.0f;

struct PointBundle {
  int64_t x = 0, y = 0, z = 0;  // sum of sensor-frame coordinates, in 2^-30 m
  uint32_t r = 0, g = 0, b = 0; // sum of colour channels
  uint32_t count = 0;
  uint32_t first = 0;           // smallest point index of the bundle
};

struct AddBundles {
  COVOX_HD_INLINE PointBundle operator()(const PointBundle& a, const PointBundle& b) const {
    PointBundle sum;
    sum.x = a.x + b.x;
    sum.y = a.y + b.y;
    sum.z = a.z + b.z;
    sum.r = a.r + b.r;
    sum.g = a.g + b.g;
    sum.b = a.b + b.b;
    sum.count = a.count + b.count;
    sum.first = a.first < b.first ? a.first : b.first;
    return sum;
  }
};

COVOX_HD_INLINE int64_t to_merge_units(float metres) {
  return static_cast<int64_t>(llrintf(metres * kMergeUnitsPerMetre));
}

// The merge key of a point's ray: the key of its surface voxel for surface rays; the codec's
// "alone" key (its zero-weight key) otherwise, which AloneKeysApart keeps from merging.
COVOX_HD_INLINE uint64_t merge_key(const RaySegment& ray, float inverse_voxel_size, const FrameKeyCodec& codec) {
  if (ray.kind == kSurfaceRay) {
    const uint64_t key = codec.key(voxel_of(ray.surface, inverse_voxel_size));
    if (key != codec.out_of_range_key) return key;
  }
  return codec.zero_weight_key;
}

// The merge keys as a reduction compares them (with ==): rays that must stay alone share the
// "alone" key, so each is given a distinct key of its own above every real key (FrameKeyCodec
// keys stay below 2^62) and the stable sort keeps them in input order.
struct AloneKeysApart {
  const uint64_t* keys;
  uint64_t alone_key;
  COVOX_HD_INLINE uint64_t operator()(int64_t i) const {
    return keys[i] == alone_key ? ~uint64_t(0) - static_cast<uint64_t>(i) : keys[i];
  }
};

}  // namespace tsdf
}  // namespace covox

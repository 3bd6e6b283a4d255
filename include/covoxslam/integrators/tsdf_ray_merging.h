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

struct alignas(16) PointBundle {  // 48 bytes: three 16-byte loads
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

// Merge keys: a surface point's key is the FrameKeyCodec key of the voxel its measured point falls
// into; points with the same key are bundled into one ray. The codec's box is fixed by the sensor
// origin and max_ray_length_m (every surface point lies within that range), so no pass over the
// points is needed before keying them. Above the codec's keys: the "alone" key (its zero-weight
// key) for rays that must not merge (clearing rays, a surface voxel outside the box), which
// AloneKeysApart keeps apart, then one key per drop reason: the dropped points of one reason form
// one bundle whose count is the number of such points, so the tally of the merged rays counts
// every input point without a tally of the points themselves.
struct MergeKeys {
  FrameKeyCodec codec;
  uint64_t alone_key = 0;    // == codec.zero_weight_key
  uint64_t dropped_key = 0;  // dropped_key + (kind - kDroppedNonFinite) for the four drop kinds
  int key_bits = 1;          // every merge key is < 2^key_bits

  COVOX_HD_INLINE uint64_t key(const RaySegment& ray, float inverse_voxel_size) const {
    if (ray.kind == kSurfaceRay) {
      const uint64_t surface_key = codec.key(voxel_of(ray.surface, inverse_voxel_size));
      if (surface_key != codec.out_of_range_key) return surface_key;
    }
    if (ray.kind > kClearingRay) return dropped_key + (ray.kind - kDroppedNonFinite);
    return alone_key;
  }
  // The keys that sum the coordinates of their points (the others keep their first point).
  COVOX_HD_INLINE bool is_surface_key(uint64_t key) const { return key < codec.out_of_range_key; }
  // The drop reason of a merged key, or kSurfaceRay when it is not a drop key.
  COVOX_HD_INLINE uint8_t dropped_kind(uint64_t key) const {
    return key >= dropped_key && key <= dropped_key + (kDroppedTooFar - kDroppedNonFinite)
               ? static_cast<uint8_t>(kDroppedNonFinite + (key - dropped_key))
               : static_cast<uint8_t>(kSurfaceRay);
  }
};

// The merge keys of a frame whose sensor sits at `origin` (world) with rays up to
// max_ray_length_m. Throws covox::Error like make_frame_key_codec for an absurdly large box.
MergeKeys make_merge_keys(const Vec3f& origin, float max_ray_length_m, float voxel_size_m, int32_t voxels_per_side);
// The same for a known box of surface voxels (the fallback when the range box needs long keys).
MergeKeys make_merge_keys(const Index3D& min_voxel, const Index3D& max_voxel, int32_t voxels_per_side);

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

// The bundle of the i-th point in key order, built where the reduction reads it (no bundle per
// point is written): a surface key sums the point's coordinates, any other key only counts it.
struct BundleOfSortedPoint {
  const Vec3f* points;
  const uint32_t* order;        // sorted position -> point index
  const uint64_t* sorted_keys;  // merge keys in sorted order
  MergeKeys merge_keys;
  const Rgb8* colors;
  const float* intensities;
  float grey_per_intensity;
  COVOX_HD_INLINE PointBundle operator()(int64_t i) const {
    const uint32_t index = order[i];
    PointBundle bundle;
    if (merge_keys.is_surface_key(sorted_keys[i])) {
      const Vec3f point = points[index];
      bundle.x = to_merge_units(point.x);
      bundle.y = to_merge_units(point.y);
      bundle.z = to_merge_units(point.z);
    }
    const Rgb8 color = color_of(colors, intensities, grey_per_intensity, index);
    bundle.r = color.r;
    bundle.g = color.g;
    bundle.b = color.b;
    bundle.count = 1;
    bundle.first = index;
    return bundle;
  }
};

}  // namespace tsdf
}  // namespace covox

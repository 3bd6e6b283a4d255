#pragma once
// Per-ray and per-voxel functions of TSDF raycast integration, shared by both backends.
#include <cmath>
#include <cstdint>
#include <cstring>

#include "covoxslam/core/atomics.h"
#include "covoxslam/core/index3d.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/core/warp_reduce.h"
#include "covoxslam/integrators/tsdf_integrator_config.h"

namespace covox::integrators::tsdf {

// Update keys name a voxel relative to the frame's bounding box of blocks: the block's position
// in the box (x fastest), then the voxel within the block. Sorting by key therefore groups a
// block's voxels together, and a frame's keys need only about 20-30 bits (log2 of the box's
// voxel count), which is all the radix sort pays for. The two values above the largest valid
// key mark updates to drop; they sort last.
struct FrameKeyCodec {
  Index3D origin_block;                        // the box's lowest block
  int32_t size_x = 1, size_y = 1, size_z = 1;  // blocks per axis
  int32_t voxels_per_side = 16;
  int voxel_bits = 12;            // bits of the voxel-within-block index
  uint64_t out_of_range_key = 0;  // a voxel outside the box (cannot happen for rays inside it)
  uint64_t zero_weight_key = 1;   // an update that carries no weight; for merging: "alone"
  int key_bits = 1;               // every key is < 2^key_bits

  // Voxels per side are a power of two (8 or 16), so the block is an arithmetic shift (a floor
  // division for negative indices too) and the voxel within it a mask: no integer division in
  // the traverse's per-voxel work.
  COVOX_HD_INLINE uint64_t key(const Index3D& voxel) const {
    const int shift = voxel_bits / 3;
    const int32_t mask = voxels_per_side - 1;
    const int32_t bx = (voxel.x >> shift) - origin_block.x,
                  by = (voxel.y >> shift) - origin_block.y,
                  bz = (voxel.z >> shift) - origin_block.z;
    if (bx < 0 || by < 0 || bz < 0 || bx >= size_x || by >= size_y || bz >= size_z)
      return out_of_range_key;
    const int32_t local =
        (voxel.x & mask) | ((voxel.y & mask) << shift) | ((voxel.z & mask) << (2 * shift));
    const uint64_t block_number =
        static_cast<uint64_t>(bx) +
        static_cast<uint64_t>(size_x) *
            (static_cast<uint64_t>(by) + static_cast<uint64_t>(size_y) * bz);
    return (block_number << voxel_bits) | static_cast<uint64_t>(local);
  }
  // Equal for all voxels of one block.
  COVOX_HD_INLINE uint64_t block_part(uint64_t key) const { return key >> voxel_bits; }
  COVOX_HD_INLINE Index3D block(uint64_t key) const {
    const uint64_t n = key >> voxel_bits;
    const uint64_t plane = static_cast<uint64_t>(size_x) * size_y;
    return Index3D(origin_block.x + static_cast<int32_t>(n % size_x),
                   origin_block.y + static_cast<int32_t>((n % plane) / size_x),
                   origin_block.z + static_cast<int32_t>(n / plane));
  }
  COVOX_HD_INLINE int32_t voxel_in_block(uint64_t key) const {
    return static_cast<int32_t>(key & ((uint64_t(1) << voxel_bits) - 1));
  }
  // The voxel a valid key names (the inverse of key()). The voxel within the block comes out by
  // shifts; keys of up to 32 bits (almost every frame) divide in 32-bit arithmetic, several times
  // cheaper on the GPU than 64-bit division.
  COVOX_HD_INLINE Index3D voxel(uint64_t key) const {
    const int shift = voxel_bits / 3;
    const int32_t mask = voxels_per_side - 1;
    const int32_t local = voxel_in_block(key);
    Index3D b;
    if (key_bits <= 32) {
      const uint32_t n = static_cast<uint32_t>(key >> voxel_bits);
      const uint32_t sx = static_cast<uint32_t>(size_x), plane = sx * static_cast<uint32_t>(size_y);
      b = Index3D(origin_block.x + static_cast<int32_t>(n % sx),
                  origin_block.y + static_cast<int32_t>((n % plane) / sx),
                  origin_block.z + static_cast<int32_t>(n / plane));
    } else {
      b = block(key);
    }
    return Index3D(b.x * voxels_per_side + (local & mask),
                   b.y * voxels_per_side + ((local >> shift) & mask),
                   b.z * voxels_per_side + (local >> (2 * shift)));
  }
};

// The codec for voxels in [min_voxel, max_voxel] (inclusive), padded by one block on every side
// so that merged rays, whose mean points can round a hair outside their points' hull, stay in.
// Throws covox::Error if the box is too large for 64-bit keys (a frame thousands of km across).
FrameKeyCodec make_frame_key_codec(const Index3D& min_voxel, const Index3D& max_voxel,
                                   int32_t voxels_per_side);

// A LiDAR intensity shown as a grey level: intensity * grey_per_intensity, clamped to 0..255.
COVOX_HD_INLINE Rgb8 intensity_to_grey(float intensity, float grey_per_intensity) {
  const float grey = intensity * grey_per_intensity;
  const uint8_t level =
      static_cast<uint8_t>(grey <= 0.0f ? 0.0f : (grey >= 255.0f ? 255.0f : grey));
  return Rgb8{level, level, level};
}

// One voxel's contribution, already multiplied by its weight so that merging updates of the
// same voxel is a plain sum (sum of w*sdf and of w, then one division). The reduction computes
// these from the visit records (tsdf_traverse.h) and sums them per voxel; 8-byte aligned so that
// a sum moves as one 64-bit word.
struct alignas(8) DistanceUpdate {
  float weighted_distance = 0.0f;
  float weight = 0.0f;
};

// The same with colour, the per-voxel sum of a coloured frame; aligned to 16 bytes (32 with
// padding) so that it moves as two 16-byte words.
struct alignas(16) VoxelUpdate {
  float weighted_distance = 0.0f;
  float weight = 0.0f;
  float weighted_r = 0.0f;
  float weighted_g = 0.0f;
  float weighted_b = 0.0f;
  float color_weight = 0.0f;
};

// A coloured frame's visit record value (tsdf_traverse.h), one 32-bit word:
// - a visit in the truncation band (or behind the surface): the index of the ray that made it,
//   with kBandVisitBit set; the reduction recomputes the update, and whether it takes the ray's
//   colour, from the ray and the voxel;
// - a visit in free space (its distance clamped to the truncation, so no colour): the bits of its
//   weight, a float >= 0 (sign bit clear), from which the update follows without the ray. With
//   carving most of a frame's visits are of this kind, and the reduction then reads no ray for
//   them.
struct ColorVisit {
  static constexpr uint32_t kBandVisitBit = 0x80000000u;
  uint32_t word = 0;
};

// The float a word's bits stand for, and back (a free-space visit's weight).
COVOX_HD_INLINE float float_of_bits(uint32_t bits) {
  float value;
  memcpy(&value, &bits, sizeof(value));
  return value;
}
COVOX_HD_INLINE uint32_t bits_of_float(float value) {
  uint32_t bits;
  memcpy(&bits, &value, sizeof(bits));
  return bits;
}

// Visits' weights and updates summed per voxel in fixed point (internal/tsdf_frame_plan.h,
// VisitMerging): integer sums are exact, so the order in which atomic adds
// arrive does not change the result (the frame stays deterministic with atomics into a scratch
// grid, never into voxels). Values go in as signed 64-bit integers (two's complement), rounded to
// the nearest unit. Weights, in both paths, take kSumUnits = 2^32 units per unit of weight: a
// voxel's weight may reach 2e9 in one frame before 64 bits overflow (an inverse-square weight is
// at most 1 / min_ray_length^2, times the points a merged ray stands for), and a weight of 1e-4
// (an inverse-square weight at 100 m) keeps 5 decimal digits.
constexpr double kSumUnits = 4294967296.0;          // 2^32 per unit of weight
constexpr double kWeightedColorUnits = 16777216.0;  // 2^24 per unit of weight x colour level
COVOX_HD_INLINE uint64_t signed_fixed_units(double value, double units_per_one) {
  return static_cast<uint64_t>(static_cast<int64_t>(floor(value * units_per_one + 0.5)));
}
COVOX_HD_INLINE double signed_fixed_value(uint64_t units, double units_per_one) {
  return static_cast<double>(static_cast<int64_t>(units)) / units_per_one;
}
// The free-space-only sums (one word per voxel): a visit's weight, and a sum's weight.
COVOX_HD_INLINE uint64_t weight_units(float weight) {
  return signed_fixed_units(weight, kSumUnits);
}
COVOX_HD_INLINE float weight_of_units(uint64_t units) {
  return static_cast<float>(signed_fixed_value(units, kSumUnits));
}

// Every visit summed: one cell per key of the frame's box, 2 64-bit words, kSumCellWords with
// colour:
//   0: the weight of all the voxel's visits, in kSumUnits;
//   1: the band visits' sum of weight x (distance / truncation - 1), in the same units (a
//      free-space visit's distance is the truncation, so it adds nothing here and one atomic in
//      all): the weighted distance is truncation x (word 0 + word 1), an exact integer sum;
//   2-5 (with colour): the colour weight in kSumUnits and the three weighted channels in
//      kWeightedColorUnits (the same overflow bound for 255 levels).
// A distance keeps 1e-5 m where the voxel's weight is 1e-5 (behind the surface, where the
// drop-off ends; with 2^28 units per unit of weight x metre such voxels differed from the float
// sums by 7e-5 m); with 2^20 colour units, colours drifted 2 levels from the float sums' over four
// frames. A visit whose weight rounds to no units adds nothing, so a cell whose word 0 is zero is
// empty.
constexpr int kSumCellWords = 6;
struct VoxelSumCells {
  uint64_t* words = nullptr;  // word w of cell k: words[k * stride + w]
  int stride = 0;             // 2 without colour, kSumCellWords with
  float truncation = 0.0f;
  // (A cell's words side by side: a cell is one or two 32-byte sectors. Each word in a plane of
  // its own over the box, or the words of neighbouring cells interleaved, spread a visit's atomics
  // and the pass's reads over more sectors.)
  COVOX_HD_INLINE uint64_t& word(uint64_t key, int w) const {
    return words[key * static_cast<uint64_t>(stride) + w];
  }
  COVOX_HD_INLINE void add(uint64_t key, const DistanceUpdate& update, bool free_space,
                           bool takes_color, const Rgb8& color) const {
    const uint64_t units = weight_units(update.weight);
    if (units == 0) return;
    if (free_space) {  // (its distance offset is zero: one atomic in all)
      atomic_add(&word(key, 0), units);
      return;
    }
    atomic_add(&word(key, 0), units);
    const double offset = static_cast<double>(update.weighted_distance) / truncation -
                          static_cast<double>(update.weight);
    atomic_add(&word(key, 1), signed_fixed_units(offset, kSumUnits));
    if (stride < kSumCellWords || !takes_color) return;
    atomic_add(&word(key, 2), units);
    atomic_add(&word(key, 3), signed_fixed_units(update.weight * color.r, kWeightedColorUnits));
    atomic_add(&word(key, 4), signed_fixed_units(update.weight * color.g, kWeightedColorUnits));
    atomic_add(&word(key, 5), signed_fixed_units(update.weight * color.b, kWeightedColorUnits));
  }
  // The cell's sum (into a zeroed `sum`) and the cell cleared; false for an empty cell.
  COVOX_HD_INLINE bool take(uint64_t key, DistanceUpdate* sum) const {
    const uint64_t units = word(key, 0);
    if (units == 0) return false;
    sum->weight = weight_of_units(units);
    sum->weighted_distance =
        static_cast<float>(signed_fixed_value(units + word(key, 1), kSumUnits) * truncation);
    word(key, 0) = 0;
    word(key, 1) = 0;
    return true;
  }
  COVOX_HD_INLINE bool take(uint64_t key, VoxelUpdate* sum) const {
    DistanceUpdate distance;
    if (!take(key, &distance)) return false;
    sum->weight = distance.weight;
    sum->weighted_distance = distance.weighted_distance;
    if (stride < kSumCellWords) return true;
    const uint64_t color_units = word(key, 2);
    if (color_units == 0) return true;
    sum->color_weight = weight_of_units(color_units);
    sum->weighted_r = static_cast<float>(signed_fixed_value(word(key, 3), kWeightedColorUnits));
    sum->weighted_g = static_cast<float>(signed_fixed_value(word(key, 4), kWeightedColorUnits));
    sum->weighted_b = static_cast<float>(signed_fixed_value(word(key, 5), kWeightedColorUnits));
    for (int w = 2; w < kSumCellWords; ++w) word(key, w) = 0;
    return true;
  }
};

// At most this many of a ray's visits lie in the truncation band (the visits that are not free
// space: a voxel's centre projects within truncation of the surface, so the ray enters it no more
// than sqrt(3)/2 voxel before that; a segment of length L crosses at most sqrt(3) L / voxel + 3
// voxel faces), with a margin for rounding.
inline int64_t band_visits_per_ray_bound(float truncation_m, float voxel_size_m) {
  return static_cast<int64_t>(1.7320508 * (2.0 * truncation_m / voxel_size_m + 1.0)) + 6;
}

// Point or ray i's colour: its own colour, else its intensity as grey, else none.
COVOX_HD_INLINE Rgb8 color_of(const Rgb8* colors, const float* intensities,
                              float grey_per_intensity, int64_t i) {
  return colors ? colors[i]
                : (intensities ? intensity_to_grey(intensities[i], grey_per_intensity) : Rgb8{});
}

struct MergeUpdates {
  COVOX_HD_INLINE DistanceUpdate operator()(const DistanceUpdate& a,
                                            const DistanceUpdate& b) const {
    DistanceUpdate sum;
    sum.weighted_distance = a.weighted_distance + b.weighted_distance;
    sum.weight = a.weight + b.weight;
    return sum;
  }
  COVOX_HD_INLINE VoxelUpdate operator()(const VoxelUpdate& a, const VoxelUpdate& b) const {
    VoxelUpdate sum;
    sum.weighted_distance = a.weighted_distance + b.weighted_distance;
    sum.weight = a.weight + b.weight;
    sum.weighted_r = a.weighted_r + b.weighted_r;
    sum.weighted_g = a.weighted_g + b.weighted_g;
    sum.weighted_b = a.weighted_b + b.weighted_b;
    sum.color_weight = a.color_weight + b.color_weight;
    return sum;
  }
};

// Why a point did or did not become a ray.
enum RayKind : uint8_t {
  kSurfaceRay = 0,   // normal: carve free space (optional) and update the truncation band
  kClearingRay = 1,  // beyond max range with allow_clear: carve free space only
  kDroppedNonFinite = 2,
  kDroppedZero = 3,
  kDroppedTooClose = 4,
  kDroppedTooFar = 5,
};

struct RaySegment {
  Vec3f start;      // world, where traversal begins
  Vec3f end;        // world, where it ends (surface + truncation, or the clearing limit)
  Vec3f surface;    // world, the measured point
  Vec3f direction;  // unit, sensor to point
  float range_m = 0.0f;
  uint8_t kind = kDroppedNonFinite;
};

struct RayParameters {
  Transform3f T_world_sensor;
  float voxel_size_m;
  float truncation_distance_m;
  float min_ray_length_m;
  float max_ray_length_m;
  bool voxel_carving_enabled;
  bool allow_clear;
};

COVOX_HD_INLINE RaySegment make_ray(const RayParameters& p, const Vec3f& point_sensor) {
  RaySegment ray;
  if (!point_sensor.is_finite()) return ray;  // kDroppedNonFinite
  const float range = point_sensor.norm();
  if (range <= 0.0f) {
    ray.kind = kDroppedZero;
    return ray;
  }
  if (range < p.min_ray_length_m) {
    ray.kind = kDroppedTooClose;
    return ray;
  }
  const Vec3f origin = p.T_world_sensor.translation;
  ray.surface = p.T_world_sensor * point_sensor;
  ray.direction = p.T_world_sensor.rotate(point_sensor) * (1.0f / range);
  ray.range_m = range;
  if (range > p.max_ray_length_m) {
    if (!p.allow_clear || !p.voxel_carving_enabled) {
      ray.kind = kDroppedTooFar;
      return ray;
    }
    ray.kind = kClearingRay;
    ray.start = origin;
    ray.end = origin + ray.direction * p.max_ray_length_m;
    return ray;
  }
  ray.kind = kSurfaceRay;
  ray.end = ray.surface + ray.direction * p.truncation_distance_m;
  ray.start =
      p.voxel_carving_enabled ? origin : ray.surface - ray.direction * p.truncation_distance_m;
  return ray;
}

COVOX_HD_INLINE Index3D voxel_of(const Vec3f& point, float inverse_voxel_size) {
  return Index3D(static_cast<int32_t>(floorf(point.x * inverse_voxel_size)),
                 static_cast<int32_t>(floorf(point.y * inverse_voxel_size)),
                 static_cast<int32_t>(floorf(point.z * inverse_voxel_size)));
}

COVOX_HD_INLINE int32_t abs_i32(int32_t v) { return v < 0 ? -v : v; }

// Voxels a segment passes through: one plus the grid lines it crosses on each axis. The
// traversal below visits exactly this many, so counting needs no traversal.
COVOX_HD_INLINE uint32_t ray_voxel_count(const RaySegment& ray, float inverse_voxel_size) {
  if (ray.kind > kClearingRay) return 0;
  const Index3D first = voxel_of(ray.start, inverse_voxel_size);
  const Index3D last = voxel_of(ray.end, inverse_voxel_size);
  return 1u + static_cast<uint32_t>(abs_i32(last.x - first.x) + abs_i32(last.y - first.y) +
                                    abs_i32(last.z - first.z));
}

// Amanatides-Woo traversal of the segment from world point `a_world` (in voxel `first`) to
// `b_world` (in voxel `last`), calling visit(voxel) for the 1 + |last - first|_1 voxels from
// `first` to `last` in order, or for all but `last` when `include_last` is false. An axis is only
// stepped while it has grid lines left to cross, so rounding can never step past `last` or change
// the count, even when `first`/`last` were clamped a voxel away from the points' own voxels.
// One axis of the walk below. The three axes are named registers, not arrays: with arrays indexed
// by the axis chosen at each step, the GPU keeps them in local memory (a stack frame per
// thread, every step a round trip through L1).
struct WalkAxis {
  int32_t position;
  int32_t remaining;  // grid lines left to cross
  int32_t step;
  float t_max;  // where along the segment (0..1) the next grid line is crossed
  float t_delta;
  COVOX_HD_INLINE WalkAxis(float a, float b, int32_t cur, int32_t end)
      : position(cur), remaining(abs_i32(end - cur)), step(end > cur ? 1 : -1) {
    const float delta = b - a;
    if (remaining == 0 || delta == 0.0f) {
      t_max = 3.0e38f;
      t_delta = 3.0e38f;
    } else {
      const float boundary = static_cast<float>(step > 0 ? cur + 1 : cur);
      t_max = (boundary - a) / delta;
      t_delta = static_cast<float>(step) / delta;
    }
  }
  COVOX_HD_INLINE void advance() {
    position += step;
    --remaining;
    t_max += t_delta;
  }
};

template <class Visitor>
COVOX_HD_INLINE void traverse_voxels(const Vec3f& a_world, const Vec3f& b_world,
                                     const Index3D& first, const Index3D& last,
                                     float inverse_voxel_size, bool include_last, Visitor&& visit) {
  const Vec3f a = a_world * inverse_voxel_size;
  const Vec3f b = b_world * inverse_voxel_size;
  WalkAxis x(a.x, b.x, first.x, last.x);
  WalkAxis y(a.y, b.y, first.y, last.y);
  WalkAxis z(a.z, b.z, first.z, last.z);
  const int32_t steps = x.remaining + y.remaining + z.remaining - (include_last ? 0 : 1);
  if (steps < 0) return;  // an empty piece: first == last and the last voxel is excluded
  visit(Index3D(x.position, y.position, z.position));
  for (int32_t k = 0; k < steps; ++k) {
    // The axis whose next grid line comes first among those with lines left; ties go to the
    // lower axis.
    const bool take_x = x.remaining > 0 && x.t_max < 3.4e38f;
    float best = take_x ? x.t_max : 3.4e38f;
    const bool take_y = y.remaining > 0 && y.t_max < best;
    best = take_y ? y.t_max : best;
    const bool take_z = z.remaining > 0 && z.t_max < best;
    if (take_z) {
      z.advance();
    } else if (take_y) {
      y.advance();
    } else if (take_x ||
               x.remaining > 0) {  // (or degenerate: a delta rounded to 0 with lines left)
      x.advance();
    } else if (y.remaining > 0) {
      y.advance();
    } else {
      z.advance();
    }
    visit(Index3D(x.position, y.position, z.position));
  }
}

// The whole ray: ray_voxel_count() voxels from ray.start to ray.end.
template <class Visitor>
COVOX_HD_INLINE void traverse_ray(const RaySegment& ray, float inverse_voxel_size,
                                  Visitor&& visit) {
  traverse_voxels(ray.start, ray.end, voxel_of(ray.start, inverse_voxel_size),
                  voxel_of(ray.end, inverse_voxel_size), inverse_voxel_size, true, visit);
}

// ---- Ray pieces --------------------------------------------------------------------------------
// One GPU thread walking a whole ray is latency bound: an RGB-D frame merges into a few thousand
// rays of up to a hundred voxels each, far too few threads to hide memory latency. So each ray is
// cut at K - 1 evenly spaced points into K pieces of about kVoxelsPerPiece voxels, one thread
// each. The cut voxels are clamped between the ray's first and last voxel, which keeps them
// monotone along every axis; a piece covers the voxels from its start cut up to, but not
// including, its end cut (the last piece includes the ray's last voxel). Monotone cuts make the
// pieces' Manhattan lengths add up to the ray's, so the pieces visit exactly ray_voxel_count()
// distinct voxels, in ray order. Both backends cut the same way.
constexpr int32_t kVoxelsPerPiece = 8;

COVOX_HD_INLINE uint32_t ray_piece_count(uint32_t voxel_count) {
  return (voxel_count + kVoxelsPerPiece - 1) / kVoxelsPerPiece;
}

// Cut point k of K (0: the ray's start, K: its end).
COVOX_HD_INLINE Vec3f ray_cut_point(const RaySegment& ray, uint32_t k, uint32_t pieces) {
  if (k == 0) return ray.start;
  if (k >= pieces) return ray.end;
  return ray.start + (ray.end - ray.start) * (static_cast<float>(k) / static_cast<float>(pieces));
}

COVOX_HD_INLINE int32_t clamp_between(int32_t v, int32_t a, int32_t b) {
  const int32_t low = a < b ? a : b, high = a < b ? b : a;
  return v < low ? low : (v > high ? high : v);
}

// A ray's first and last voxel, which every cut is clamped between.
struct RayEndVoxels {
  Index3D first;
  Index3D last;
};
COVOX_HD_INLINE RayEndVoxels ray_end_voxels(const RaySegment& ray, float inverse_voxel_size) {
  return RayEndVoxels{voxel_of(ray.start, inverse_voxel_size),
                      voxel_of(ray.end, inverse_voxel_size)};
}

COVOX_HD_INLINE Index3D ray_cut_voxel(const RaySegment& ray, const RayEndVoxels& ends, uint32_t k,
                                      uint32_t pieces, float inverse_voxel_size) {
  if (k == 0) return ends.first;
  if (k >= pieces) return ends.last;
  const Index3D v = voxel_of(ray_cut_point(ray, k, pieces), inverse_voxel_size);
  return Index3D(clamp_between(v.x, ends.first.x, ends.last.x),
                 clamp_between(v.y, ends.first.y, ends.last.y),
                 clamp_between(v.z, ends.first.z, ends.last.z));
}
COVOX_HD_INLINE Index3D ray_cut_voxel(const RaySegment& ray, uint32_t k, uint32_t pieces,
                                      float inverse_voxel_size) {
  return ray_cut_voxel(ray, ray_end_voxels(ray, inverse_voxel_size), k, pieces, inverse_voxel_size);
}

// Voxels of the piece from cut voxel a to cut voxel b (the last piece includes b).
COVOX_HD_INLINE uint32_t piece_voxel_count(const Index3D& a, const Index3D& b, bool last_piece) {
  return static_cast<uint32_t>(abs_i32(b.x - a.x) + abs_i32(b.y - a.y) + abs_i32(b.z - a.z)) +
         (last_piece ? 1u : 0u);
}

// Voxels piece k of `pieces` visits.
COVOX_HD_INLINE uint32_t ray_piece_voxel_count(const RaySegment& ray, uint32_t k, uint32_t pieces,
                                               float inverse_voxel_size) {
  const RayEndVoxels ends = ray_end_voxels(ray, inverse_voxel_size);
  return piece_voxel_count(ray_cut_voxel(ray, ends, k, pieces, inverse_voxel_size),
                           ray_cut_voxel(ray, ends, k + 1, pieces, inverse_voxel_size),
                           k + 1 == pieces);
}

// A ray's `pieces` pieces in order, each cut voxel computed once (it ends one piece and starts the
// next): emit(k, first voxel of piece k, voxels of piece k). The same cuts and counts as
// ray_cut_voxel and ray_piece_voxel_count give piece by piece (the CPU twin's piece table).
template <class Emit>
COVOX_HD_INLINE void for_each_ray_piece(const RaySegment& ray, uint32_t pieces,
                                        float inverse_voxel_size, Emit&& emit) {
  const RayEndVoxels ends = ray_end_voxels(ray, inverse_voxel_size);
  Index3D start = ends.first;
  for (uint32_t k = 0; k < pieces; ++k) {
    const Index3D end = ray_cut_voxel(ray, ends, k + 1, pieces, inverse_voxel_size);
    emit(k, start, piece_voxel_count(start, end, k + 1 == pieces));
    start = end;
  }
}

// Piece k of `pieces`, from cut voxel `first` to cut voxel `last` (computed by the caller).
template <class Visitor>
COVOX_HD_INLINE void traverse_ray_piece(const RaySegment& ray, uint32_t k, uint32_t pieces,
                                        const Index3D& first, const Index3D& last,
                                        float inverse_voxel_size, Visitor&& visit) {
  traverse_voxels(ray_cut_point(ray, k, pieces), ray_cut_point(ray, k + 1, pieces), first, last,
                  inverse_voxel_size, k + 1 == pieces, visit);
}
template <class Visitor>
COVOX_HD_INLINE void traverse_ray_piece(const RaySegment& ray, uint32_t k, uint32_t pieces,
                                        float inverse_voxel_size, Visitor&& visit) {
  const RayEndVoxels ends = ray_end_voxels(ray, inverse_voxel_size);
  traverse_ray_piece(ray, k, pieces, ray_cut_voxel(ray, ends, k, pieces, inverse_voxel_size),
                     ray_cut_voxel(ray, ends, k + 1, pieces, inverse_voxel_size),
                     inverse_voxel_size, visit);
}

// Which ray a piece belongs to, and which of its pieces it is.
struct RayPiece {
  uint32_t ray;
  uint32_t index;
  uint32_t pieces;
};

struct WeightParameters {
  float voxel_size_m;
  float truncation_distance_m;
  bool use_const_weight;
  bool use_weight_dropoff;
  bool use_sparsity_compensation_factor;
  float sparsity_compensation_factor;
};

// What the per-voxel stages of a frame need from the ray stages (device pointers).
struct FrameUpdates {
  FrameKeyCodec codec;
  int64_t total_updates;
  int64_t piece_bound;
  const uint32_t* piece_total;  // on the device
  const RayPiece* pieces;
  // Each piece's first voxel (its cut voxel), where the piece table was written with them (the
  // CPU twin); null: the traverse computes both cuts of a piece (the GPU).
  const Index3D* piece_first_voxels;
  const RaySegment* rays;
  const Rgb8* colors;
  const float* intensities;
  float grey_per_intensity;
  const float* ray_weights;
  float inverse_voxel_size;
  float voxel_size;
  WeightParameters weight_parameters;
  // When every visit is summed, the rays are walked in groups (tsdf_traverse.h, RayGroups) and
  // there is no piece table: each ray's piece count, and the most pieces of any ray.
  bool walks_ray_groups = false;  // false: walked by the piece table
  const uint32_t* ray_pieces = nullptr;
  uint32_t most_ray_pieces = 0;
  int64_t ray_count = 0;
};

// Where pixel (u, v) of a width x height image goes in the frame's point order: tiles of
// kPixelTileWidth x kPixelTileHeight pixels (one GPU warp's 32 points), the tiles of each band of
// rows left to right, the bands top to bottom, each tile's pixels row by row (the right and
// bottom tiles are narrower or lower when the image's size is not a multiple of theirs).
// Neighbouring points then lie together in both directions: a warp of the merge sees a compact
// patch of pixels, which falls into few bundles, and the merged rays, ranked by their first
// point, come in spatial patches, which the ray groups walk side by side (tsdf_traverse.h).
constexpr int32_t kPixelTileWidth = 8;
constexpr int32_t kPixelTileHeight = 4;
COVOX_HD_INLINE int64_t pixel_tile_order(int32_t u, int32_t v, int32_t width, int32_t height) {
  const int32_t band = v / kPixelTileHeight;
  const int32_t band_rows = height - band * kPixelTileHeight;
  const int32_t band_height = band_rows < kPixelTileHeight ? band_rows : kPixelTileHeight;
  const int32_t column = u / kPixelTileWidth;
  const int32_t tile_columns = width - column * kPixelTileWidth;
  const int32_t tile_width = tile_columns < kPixelTileWidth ? tile_columns : kPixelTileWidth;
  return static_cast<int64_t>(band) * kPixelTileHeight * width +
         static_cast<int64_t>(column) * kPixelTileWidth * band_height +
         (v % kPixelTileHeight) * tile_width + (u % kPixelTileWidth);
}

// The inverse of pixel_tile_order: the row-major index (v * width + u) of the pixel at `place`.
// Every band but the last is full height and every tile but a band's last is full width, so
// the band and the tile follow by division.
COVOX_HD_INLINE int64_t pixel_at_tile_place(int64_t place, int32_t width, int32_t height) {
  const int64_t band_pixels = static_cast<int64_t>(kPixelTileHeight) * width;
  const int32_t band = static_cast<int32_t>(place / band_pixels);
  const int32_t in_band = static_cast<int32_t>(place - band * band_pixels);
  const int32_t band_rows = height - band * kPixelTileHeight;
  const int32_t band_height = band_rows < kPixelTileHeight ? band_rows : kPixelTileHeight;
  const int32_t column = in_band / (kPixelTileWidth * band_height);
  const int32_t in_tile = in_band - column * kPixelTileWidth * band_height;
  const int32_t tile_columns = width - column * kPixelTileWidth;
  const int32_t tile_width = tile_columns < kPixelTileWidth ? tile_columns : kPixelTileWidth;
  const int32_t v = band * kPixelTileHeight + in_tile / tile_width;
  const int32_t u = column * kPixelTileWidth + in_tile % tile_width;
  return static_cast<int64_t>(v) * width + u;
}

// A depth image (device memory, row-major) read as a frame's points in tile order: point `place`
// is the pixel pixel_at_tile_place(place) unprojected, ((u - cx) z / fx, (v - cy) z / fy, z), or
// the zero point (dropped and counted as such) where the pixel has no measurement. Both the
// unprojection kernel and the merge (which reads the image in place:
// internal/tsdf_stage_merge_rays.h) compute the points with this one function, so they agree bit
// for bit.
struct DepthImagePoints {
  const uint16_t* depth = nullptr;  // raw units, or
  const float* depth_m = nullptr;   // metres (NaN, Inf, 0 or negative: no measurement)
  const Rgb8* colors = nullptr;     // optional, registered to the depth image
  float metres_per_unit = 1e-3f;
  uint16_t invalid_value = 0;  // besides 0
  float inverse_fx = 1.0f, inverse_fy = 1.0f, cx = 0.0f, cy = 0.0f;
  int32_t width = 0, height = 0;

  COVOX_HD_INLINE int64_t pixels() const { return static_cast<int64_t>(width) * height; }
  COVOX_HD_INLINE int64_t pixel_at(int64_t place) const {
    return pixel_at_tile_place(place, width, height);
  }
  COVOX_HD_INLINE Vec3f point(int64_t pixel) const {
    float z = 0.0f;
    if (depth_m) {
      z = depth_m[pixel];
      if (!(z > 0.0f) || !(z < 3.0e38f)) z = 0.0f;
    } else {
      const uint16_t raw = depth[pixel];
      z = (raw == 0 || raw == invalid_value) ? 0.0f : raw * metres_per_unit;
    }
    if (z == 0.0f) return Vec3f(0.0f, 0.0f, 0.0f);
    const int32_t u = static_cast<int32_t>(pixel % width), v = static_cast<int32_t>(pixel / width);
    return Vec3f((static_cast<float>(u) - cx) * z * inverse_fx,
                 (static_cast<float>(v) - cy) * z * inverse_fy, z);
  }
};

// voxblox's weighting. The inverse-square term uses the measured range rather than the
// camera z: for a LiDAR, z is height, not depth (for a depth camera near the image centre the
// two agree).
COVOX_HD_INLINE float update_weight(const WeightParameters& p, float range_m, float distance_m) {
  float weight = p.use_const_weight ? 1.0f : (range_m > 1e-6f ? 1.0f / (range_m * range_m) : 1.0f);
  if (p.use_weight_dropoff && distance_m < -p.voxel_size_m) {
    weight *= (p.truncation_distance_m + distance_m) / (p.truncation_distance_m - p.voxel_size_m);
    weight = weight > 0.0f ? weight : 0.0f;
  }
  if (p.use_sparsity_compensation_factor && fabsf(distance_m) < p.truncation_distance_m) {
    weight *= p.sparsity_compensation_factor;
  }
  return weight;
}

}  // namespace covox::integrators::tsdf

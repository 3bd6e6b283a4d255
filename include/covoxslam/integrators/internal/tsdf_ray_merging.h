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
#include <climits>
#include <cstdint>

#include "covoxslam/core/atomics.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox::integrators::tsdf {

// 2^30 units per metre: every float coordinate of magnitude >= 2^-7 m is a whole number of units
// (its ulp is at least 2^-30), so the mean of identical points is the point itself; and 64-bit
// sums of 4 million points up to kMaxMergedRange_m away cannot overflow (2^22 * 2^10 * 2^30).
constexpr float kMergeUnitsPerMetre = 1073741824.0f;
constexpr float kMaxMergedRange_m = 1000.0f;

struct alignas(16) PointBundle {  // 48 bytes: three 16-byte loads
  int64_t x = 0, y = 0, z = 0;    // sum of sensor-frame coordinates, in 2^-30 m
  uint32_t r = 0, g = 0, b = 0;   // sum of colour channels
  uint32_t count = 0;
  uint32_t first = 0;  // smallest point index of the bundle
};

COVOX_HD_INLINE int64_t to_merge_units(float metres) {
  return static_cast<int64_t>(llrintf(metres * kMergeUnitsPerMetre));
}

// What a point became in the merge: its bundle's slot, or one of these (above every slot).
constexpr uint32_t kAlonePoint = 0xFFFFFFFFu;        // a ray of its own (clearing, outside the box)
constexpr uint32_t kDroppedPointCode = 0xFFFFFFF0u;  // + (kind - kDroppedNonFinite): counted only
COVOX_HD_INLINE bool is_bundle_slot(uint32_t code) { return code < kDroppedPointCode; }
COVOX_HD_INLINE bool is_dropped_code(uint32_t code) {
  return code >= kDroppedPointCode && code != kAlonePoint;
}
COVOX_HD_INLINE uint8_t dropped_kind_of_code(uint32_t code) {
  return static_cast<uint8_t>(kDroppedNonFinite + (code - kDroppedPointCode));
}

// Merge keys: a surface point's key is the FrameKeyCodec key of the voxel its measured point falls
// into; points with the same key are bundled into one ray. The codec's box is fixed by the sensor
// origin and max_ray_length_m (every surface point lies within that range), so no pass over the
// points is needed before keying them.
struct MergeKeys {
  FrameKeyCodec codec;

  // What point `index` with ray `ray` becomes: a bundle (its key, returned through `key`), a ray
  // of its own (kAlonePoint: a clearing ray, or a surface voxel outside the box), or a drop.
  COVOX_HD_INLINE uint32_t classify(const RaySegment& ray, float inverse_voxel_size,
                                    uint64_t* key) const {
    if (ray.kind == kSurfaceRay) {
      *key = codec.key(voxel_of(ray.surface, inverse_voxel_size));
      return *key != codec.out_of_range_key ? 0u : kAlonePoint;
    }
    if (ray.kind == kClearingRay) return kAlonePoint;
    return kDroppedPointCode + (ray.kind - kDroppedNonFinite);
  }
};

// The merge keys of a frame whose sensor sits at `origin` (world) with rays up to
// max_ray_length_m. Throws covox::Error like make_frame_key_codec for an absurdly large box.
MergeKeys make_merge_keys(const Vec3f& origin, float max_ray_length_m, float voxel_size_m,
                          int32_t voxels_per_side);

// The frame's bundles, gathered without sorting the points: an open-addressing hash table from
// merge key to bundle, filled with integer atomics. The sums are integers (and `first` a minimum),
// so a bundle comes out the same whatever order the points arrive in; which slot a key lands in
// does depend on that order, so nothing downstream reads slots in slot order: each bundle is
// emitted as a ray by its first point, and the rays are ranked by that point's index (a scan), an
// order that is the same on both backends and in every run. These are atomics on scratch sums of
// points, not on voxel data: the voxels are still written once each, after a sort by key.
//
// Free slots hold kFreeMergeKey and an empty bundle (first == kNoPoint). The table is cleaned as
// it is used: the kernel that turns each bundle into a ray frees its slot, so a frame leaves the
// table as it found it and no frame pays for clearing all of it.
constexpr uint64_t kFreeMergeKey = ~uint64_t(0);
constexpr uint32_t kNoPoint = 0xFFFFFFFFu;

struct MergeTable {
  uint64_t* keys;
  PointBundle* bundles;
  uint32_t mask;  // capacity - 1; the capacity is a power of two, at least twice the points
  int shift;      // 64 - log2(capacity): the hash keeps the product's top bits

  COVOX_HD_INLINE uint32_t home_slot(uint64_t key) const {
    return static_cast<uint32_t>((key * 0x9E3779B97F4A7C15ull) >> shift) & mask;
  }
  // The slot of `key`, claimed if no point of the frame claimed it yet. Linear probing; the table
  // is never more than half full, so the probe ends.
  COVOX_HD_INLINE uint32_t slot_of(uint64_t key) const {
    uint32_t slot = home_slot(key);
    while (true) {
      const uint64_t there = atomic_load_relaxed(&keys[slot]);
      if (there == key) return slot;
      if (there == kFreeMergeKey) {
        const uint64_t before = atomic_compare_exchange(&keys[slot], kFreeMergeKey, key);
        if (before == kFreeMergeKey || before == key) return slot;
      }
      slot = (slot + 1) & mask;
    }
  }
  // Adds the sums of some of a bundle's points (a warp's, warp_reduce.h) to the bundle.
  COVOX_HD_INLINE void add(uint32_t slot, const PointBundle& sums, bool has_color) const {
    PointBundle& bundle = bundles[slot];
    atomic_add(reinterpret_cast<uint64_t*>(&bundle.x), static_cast<uint64_t>(sums.x));
    atomic_add(reinterpret_cast<uint64_t*>(&bundle.y), static_cast<uint64_t>(sums.y));
    atomic_add(reinterpret_cast<uint64_t*>(&bundle.z), static_cast<uint64_t>(sums.z));
    if (has_color) {
      atomic_add(&bundle.r, sums.r);
      atomic_add(&bundle.g, sums.g);
      atomic_add(&bundle.b, sums.b);
    }
    atomic_add(&bundle.count, sums.count);
    atomic_min(&bundle.first, sums.first);
  }
  COVOX_HD_INLINE void free_slot(uint32_t slot) const {
    keys[slot] = kFreeMergeKey;
    PointBundle empty;
    empty.first = kNoPoint;
    bundles[slot] = empty;
  }
};

// What a frame's merge made of its points, counted with integer atomics as the rays are written
// (the same sums in any order): points per kind (a ray counts the points it stands for), rays
// cast, rays written, voxels their traversal will visit, and the box of those voxels.
// Thousands of warps add to these counters, and atomics on one cache line queue in one slice of
// the GPU's L2: the counters are kept in kMergeTallyStripes copies, each on its own line, a warp
// adding to the copy of its index, and the copies are summed at the end (the GPU's last warp:
// MergeTallySummary; the CPU twin's host, from a 4 KB read-back). More copies spread the atomics
// further but cost their sum and reset.
struct alignas(128) MergeTallyStripe {
  uint64_t kinds[6];
  uint64_t cast;
  uint64_t rays;
  uint64_t voxels;
  int32_t low[3];
  int32_t high[3];
  int32_t most_pieces;  // the longest ray's pieces (tsdf_kernels.h, ray_piece_count)
  // Field by field, each a plain store (no temporary stripe built and copied).
  COVOX_HD_INLINE void reset() {
    for (int k = 0; k < 6; ++k) kinds[k] = 0;
    cast = rays = voxels = 0;
    most_pieces = 0;
    for (int axis = 0; axis < 3; ++axis) {
      low[axis] = INT32_MAX;
      high[axis] = INT32_MIN;
    }
  }
};
constexpr int kMergeTallyStripes = 32;
// The copy that the warp of item i adds to.
COVOX_HD_INLINE int merge_tally_stripe(int64_t i) {
  return static_cast<int>((i >> 5) & (kMergeTallyStripes - 1));
}
struct MergeTally {
  MergeTallyStripe stripes[kMergeTallyStripes];
};

// The GPU's hand-off of the tally: the ray kernel's warps count themselves done once their atomics
// are out, and the last one sums the stripes into a MergeTallySummary in page-locked host memory
// that the kernel writes directly (MappedHostBytes, memory.h), stamped with the frame's sequence
// number; the host reads it after its wait, without a 4 KB copy queued after the kernel.
struct MergeTallySummary {
  MergeTallyStripe sum;
  uint32_t sequence = 0;
};
// The stripes' sum by the calling warp's `lanes`: each lane reads some stripes (volatile loads:
// what the other warps' atomics left in L2, not a stale line of this multiprocessor's L1), then
// the warp reduces; every lane gets the sum.
COVOX_HD_INLINE MergeTallyStripe sum_merge_tally_stripes(const MergeTallyStripe* stripes,
                                                         uint32_t lanes) {
  MergeTallyStripe part;
  part.reset();
  const int lane_count = static_cast<int>(warp_count(lanes));
  const int rank = static_cast<int>(warp_count(lanes & ((1u << warp_lane()) - 1u)));
  for (int k = rank; k < kMergeTallyStripes; k += lane_count) {
    const volatile MergeTallyStripe& stripe = stripes[k];
    for (int kind = 0; kind < 6; ++kind) part.kinds[kind] += stripe.kinds[kind];
    part.cast += stripe.cast;
    part.rays += stripe.rays;
    part.voxels += stripe.voxels;
    part.most_pieces =
        part.most_pieces > stripe.most_pieces ? part.most_pieces : stripe.most_pieces;
    for (int axis = 0; axis < 3; ++axis) {
      part.low[axis] = part.low[axis] < stripe.low[axis] ? part.low[axis] : stripe.low[axis];
      part.high[axis] = part.high[axis] > stripe.high[axis] ? part.high[axis] : stripe.high[axis];
    }
  }
  MergeTallyStripe sum;
  for (int kind = 0; kind < 6; ++kind) sum.kinds[kind] = warp_sum(lanes, part.kinds[kind]);
  sum.cast = warp_sum(lanes, part.cast);
  sum.rays = warp_sum(lanes, part.rays);
  sum.voxels = warp_sum(lanes, part.voxels);
  sum.most_pieces = warp_max(lanes, part.most_pieces);
  for (int axis = 0; axis < 3; ++axis) {
    sum.low[axis] = warp_min(lanes, part.low[axis]);
    sum.high[axis] = warp_max(lanes, part.high[axis]);
  }
  return sum;
}

}  // namespace covox::integrators::tsdf

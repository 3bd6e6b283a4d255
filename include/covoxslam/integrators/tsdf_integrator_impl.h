#pragma once
// Definitions of the TSDF integration steps (see tsdf_integrator.h for the algorithm), written
// once for both backends.
#include <algorithm>
#include <climits>
#include <string>

#include <array>
#include <type_traits>

#include <thrust/functional.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/reduce.h>

#include "covoxslam/core/eigen_conversions.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/radix_sort.h"
#include "covoxslam/core/run_sums.h"
#include "covoxslam/core/sorted_search.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/core/warp_reduce.h"
#include "covoxslam/integrators/tsdf_group_updates_cpu.h"
#include "covoxslam/integrators/tsdf_integrator_ops.h"
#include "covoxslam/integrators/tsdf_traverse.h"

namespace covox {
namespace tsdf_detail {

// Points per kind, rays cast, the total voxel count and the box of voxels the rays traverse, in
// one reduction (one read-back, not ten). The box sizes the frame's update keys.
struct RayTally {
  int64_t kinds[6] = {0, 0, 0, 0, 0, 0};  // input points, by what became of them
  int64_t cast = 0;                       // surface and clearing rays (after merging)
  int64_t rays = 0;                       // merged rays, of every kind
  int64_t voxels = 0;
  int32_t low[3] = {INT32_MAX, INT32_MAX, INT32_MAX};
  int32_t high[3] = {INT32_MIN, INT32_MIN, INT32_MIN};

  Index3D low_voxel() const { return Index3D(low[0], low[1], low[2]); }
  Index3D high_voxel() const { return Index3D(high[0], high[1], high[2]); }
};
// The tally of one ray that stands for `points` input points (a merged bundle's count; 1 without
// merging).
COVOX_HD_INLINE RayTally tally_ray(const tsdf::RaySegment& ray, int64_t points, float inverse_voxel_size) {
  RayTally tally;
  tally.kinds[ray.kind] = points;
  tally.cast = ray.kind <= tsdf::kClearingRay ? 1 : 0;
  tally.voxels = tsdf::ray_voxel_count(ray, inverse_voxel_size);
  if (ray.kind <= tsdf::kClearingRay) {  // a segment's voxels lie in the box of its end voxels
    const Index3D a = tsdf::voxel_of(ray.start, inverse_voxel_size);
    const Index3D b = tsdf::voxel_of(ray.end, inverse_voxel_size);
    const int32_t av[3] = {a.x, a.y, a.z}, bv[3] = {b.x, b.y, b.z};
    for (int axis = 0; axis < 3; ++axis) {
      tally.low[axis] = av[axis] < bv[axis] ? av[axis] : bv[axis];
      tally.high[axis] = av[axis] > bv[axis] ? av[axis] : bv[axis];
    }
  }
  return tally;
}
// The tally of a point's own ray, computed from the point (no ray array written).
struct TallyPoint {
  tsdf::RayParameters ray_parameters;
  float inverse_voxel_size;
  COVOX_HD_INLINE RayTally operator()(const Vec3f& point) const {
    return tally_ray(tsdf::make_ray(ray_parameters, point), 1, inverse_voxel_size);
  }
};
struct AddTallies {
  COVOX_HD_INLINE RayTally operator()(const RayTally& a, const RayTally& b) const {
    RayTally sum;
    for (int k = 0; k < 6; ++k) sum.kinds[k] = a.kinds[k] + b.kinds[k];
    sum.cast = a.cast + b.cast;
    sum.rays = a.rays + b.rays;
    sum.voxels = a.voxels + b.voxels;
    for (int axis = 0; axis < 3; ++axis) {
      sum.low[axis] = a.low[axis] < b.low[axis] ? a.low[axis] : b.low[axis];
      sum.high[axis] = a.high[axis] > b.high[axis] ? a.high[axis] : b.high[axis];
    }
    return sum;
  }
};

// Step 5's terms when the records are sums already (no colour, or the CPU twin's merged voxels).
template <class SumT>
struct ArrayTerm {
  const SumT* sums;
  COVOX_HD_INLINE SumT operator()(int64_t j) const { return sums[j]; }
};

// Step 5's colour blend: a frame without colour (DistanceUpdate) has none to blend. (Overloads,
// not `if constexpr`: nvcc's extended lambdas may not first-capture inside a constexpr if.)
template <class ColorView>
COVOX_HD_INLINE void blend_color(const ColorView&, int64_t, const tsdf::DistanceUpdate&, float) {}
template <class ColorView>
COVOX_HD_INLINE void blend_color(const ColorView& color_view, int64_t index, const tsdf::VoxelUpdate& update,
                                 float max_weight) {
  if (update.color_weight <= 0.0f) return;
  ColorVoxel color = color_view.load(index);
  const float color_combined = color.weight + update.color_weight;
  const float old_part = color.weight / color_combined;
  const float inverse_new = 1.0f / color_combined;
  color.r = static_cast<uint8_t>(fminf(255.0f, color.r * old_part + update.weighted_r * inverse_new + 0.5f));
  color.g = static_cast<uint8_t>(fminf(255.0f, color.g * old_part + update.weighted_g * inverse_new + 0.5f));
  color.b = static_cast<uint8_t>(fminf(255.0f, color.b * old_part + update.weighted_b * inverse_new + 0.5f));
  color.weight = color_combined < max_weight ? color_combined : max_weight;
  color_view.store(index, color);
}

// Copies the first N figures left on the device (scratch.readback) to the host: one small copy,
// one wait.
template <size_t N>
std::array<uint32_t, N> read_back(const TsdfScratchBuffers& scratch, const Stream& stream) {
  static_assert(N <= 8, "read_back: the frame's figures are 8 words");
  std::array<uint32_t, N> host{};
  copy_bytes(host.data(), Device::kCpu, scratch.readback.data(), scratch.readback.device(), N * sizeof(uint32_t),
             stream);
  return host;
}

// The merge table for a frame of n points: at least twice n slots (a power of two), all free.
// A frame frees the slots it used (tsdf_merge_rays), so the table is cleared only when it grows
// or when the last frame did not get that far (an exception between its kernels).
template <class Backend>
tsdf::MergeTable clean_merge_table(Backend backend, TsdfScratchBuffers& scratch, int64_t n, const Stream& stream) {
  int log2_capacity = 10;
  while ((int64_t(1) << log2_capacity) < 2 * n) ++log2_capacity;
  const int64_t capacity = int64_t(1) << log2_capacity;
  if (log2_capacity > 31) throw Error("TSDF integrator: " + std::to_string(n) + " points in one frame are too many to merge");
  if (static_cast<int64_t>(scratch.merge_table_keys.size()) < capacity || !scratch.merge_table_clean) {
    const int64_t size = std::max<int64_t>(capacity, static_cast<int64_t>(scratch.merge_table_keys.size()));
    scratch.merge_table_keys.resize_discard(size);
    scratch.merge_table_bundles.resize_discard(size);
    const tsdf::MergeTable all{scratch.merge_table_keys.data(), scratch.merge_table_bundles.data(), 0u, 0};
    parallel_for(backend, stream, size, [=] COVOX_HD(int64_t slot) { all.free_slot(static_cast<uint32_t>(slot)); });
  }
  scratch.merge_table_clean = false;  // until the frame's last merge kernel has freed its slots
  return tsdf::MergeTable{scratch.merge_table_keys.data(), scratch.merge_table_bundles.data(),
                          static_cast<uint32_t>(capacity - 1), 64 - log2_capacity};
}

}  // namespace tsdf_detail

// Bundles surface rays by the voxel their point falls into and writes scratch.rays with one ray
// per bundle and one per point that stays alone (clearing rays, surface voxels outside the merge
// box), ranked by the index of the point that emits it (see tsdf_ray_merging.h), with the number
// of points each stands for in scratch.ray_weights and, when `has_color`, its mean colour in
// scratch.ray_colors; each ray's piece count goes to scratch.counts, with a 0 after the last ray.
// Returns the tally of the points and rays (one read-back, the merge's only wait).
template <class Backend>
tsdf_detail::RayTally tsdf_merge_rays(Backend backend, const tsdf::RayParameters& ray_parameters,
                                      const tsdf::MergeKeys& merge_keys, const PointCloudView& cloud,
                                      const Rgb8* colors, const float* intensities, float grey_per_intensity,
                                      TsdfScratchBuffers& scratch, const Stream& stream) {
  StageProfiler::Scope profile("tsdf merge", stream);
  const int64_t n = cloud.count;
  const float inverse_voxel_size = 1.0f / ray_parameters.voxel_size_m;
  const tsdf::MergeTable table = tsdf_detail::clean_merge_table(backend, scratch, n, stream);
  // The tally is reset after the last frame's read-back, where the GPU waits for the host's next
  // launches anyway (here it cost 2.4 us + a launch gap per frame), unless that frame did not get
  // that far.
  const bool tally_clean = scratch.merge_tally_clean && scratch.merge_tally.size() == 1;
  scratch.merge_tally.resize_discard(1);
  tsdf::MergeTallyStripe* stripes = scratch.merge_tally.data()->stripes;
  const auto reset_tally = [&] {
    parallel_for(backend, stream, tsdf::kMergeTallyStripes, [=] COVOX_HD(int64_t k) { stripes[k].reset(); });
  };
  if (!tally_clean) reset_tally();
  scratch.merge_tally_clean = false;
  profile.mark("table");
  scratch.point_codes.resize_discard(n);
  uint32_t* codes = scratch.point_codes.data();
  const Vec3f* points = cloud.points;
  const bool has_color = colors || intensities;
  // Points of one voxel lie within 2^31 merge units of each other (per axis) when the voxel's
  // diagonal is under about 1.8 m (voxels under 1 m): their coordinates sum in two warp reductions
  // each instead of four (warp_sum_clustered).
  const bool clustered = ray_parameters.voxel_size_m * 1.7320508f * tsdf::kMergeUnitsPerMetre < 2.0e9f;
  // Every point: its ray, its bundle (claimed or found in the table), its sums added. A warp's
  // points of one bundle add their sums together, one atomic per field (warp_reduce.h): a 5 cm
  // voxel holds about 80 pixels of a depth image, whose atomics would otherwise queue up. Each
  // group of a warp's lanes reduces in turn, so the reductions are few: the count and the first
  // point come from the group's mask (the lanes of a warp hold consecutive points), two colour
  // channels share a word (a sum of 32 is at most 8160).
  parallel_for(backend, stream, n, [=] COVOX_HD(int64_t i) {
    const uint32_t lanes = warp_lanes();
    const Vec3f point = points[i];
    uint64_t key = 0;
    uint32_t code = merge_keys.classify(tsdf::make_ray(ray_parameters, point), inverse_voxel_size, &key);
    if (code != 0u) key = tsdf::kFreeMergeKey;  // no bundle
    const Rgb8 color = tsdf::color_of(colors, intensities, grey_per_intensity, i);
    // The warp's points of one bundle (equal keys) reduce among themselves, all bundles at once.
    const uint32_t peers = warp_match(lanes, key);
    const int leader = warp_first_lane(peers);
    if (key != tsdf::kFreeMergeKey) {  // the same for all peers
      tsdf::PointBundle sums;
      const auto sum_units = [peers, clustered](float metres) {
        const int64_t units = tsdf::to_merge_units(metres);
        return clustered ? warp_sum_clustered(peers, units)
                         : static_cast<int64_t>(warp_sum(peers, static_cast<uint64_t>(units)));
      };
      sums.x = sum_units(point.x);
      sums.y = sum_units(point.y);
      sums.z = sum_units(point.z);
      if (has_color) {
        const uint32_t red_green = warp_sum(peers, static_cast<uint32_t>(color.r) | (static_cast<uint32_t>(color.g) << 16));
        sums.r = red_green & 0xFFFFu;
        sums.g = red_green >> 16;
        sums.b = warp_sum(peers, static_cast<uint32_t>(color.b));
      }
      sums.count = warp_count(peers);
      sums.first = static_cast<uint32_t>(i - warp_lane() + leader);  // the group's lowest lane
      uint32_t slot = 0;
      if (warp_lane() == leader) {
        slot = table.slot_of(key);
        table.add(slot, sums, has_color);
      }
      code = warp_broadcast(peers, slot, leader);
    }
    codes[i] = code;
    // Dropped points are only counted, per warp.
    if (warp_ballot(lanes, tsdf::is_dropped_code(code)) == 0u) return;
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t dropped = warp_sum(lanes, code == tsdf::kDroppedPointCode + k ? 1u : 0u);
      if (dropped != 0u && warp_lane() == warp_first_lane(lanes)) {
        atomic_add(&stripes[tsdf::merge_tally_stripe(i)].kinds[tsdf::kDroppedNonFinite + k], static_cast<uint64_t>(dropped));
      }
    }
  });
  profile.mark("bundle");
  // Which points emit a ray, and its rank among the rays (point order: the same on both backends).
  scratch.ray_flags.resize_discard(n + 1);
  scratch.ray_ranks.resize_discard(n + 1);
  uint32_t* emits_ray = scratch.ray_flags.data();
  uint32_t* ray_rank = scratch.ray_ranks.data();
  const tsdf::PointBundle* bundles = table.bundles;
  parallel_for(backend, stream, n + 1, [=] COVOX_HD(int64_t i) {
    if (i == n) {
      emits_ray[n] = 0;
      return;
    }
    const uint32_t code = codes[i];
    emits_ray[i] = code == tsdf::kAlonePoint ||
                           (tsdf::is_bundle_slot(code) && bundles[code].first == static_cast<uint32_t>(i))
                       ? 1u
                       : 0u;
  });
  exclusive_scan(backend, stream, static_cast<const uint32_t*>(emits_ray), n + 1, ray_rank);
  profile.mark("rank");
  scratch.rays.resize_discard(n);
  scratch.ray_weights.resize_discard(n);
  scratch.ray_colors.resize_discard(n);
  scratch.counts.resize_discard(n + 1);
  uint32_t* ray_pieces = scratch.counts.data();
  tsdf::RaySegment* merged_rays = scratch.rays.data();
  float* weights = scratch.ray_weights.data();
  Rgb8* ray_colors = scratch.ray_colors.data();
  // Each emitting point writes its ray, frees its bundle's slot (the table is clean again) and,
  // on the GPU, adds its ray to the tally, per warp. On the CPU twin a "warp" is one call, so the
  // tally's atomics would be one per ray and counter, on lines both cores write: the rays are
  // tallied by a reduction afterwards instead (2-core CPU, OS1-64 scan: this step 3.0 -> 0.6-0.9
  // ms, the reduction 0.2-0.3 ms; the whole merge 4.5 -> 2.5 ms).
  constexpr bool kTallyWithAtomics = Backend::kDevice != Device::kCpu;
  parallel_for(backend, stream, n + 1, [=] COVOX_HD(int64_t i) {
    const uint32_t lanes = warp_lanes();
    const bool emits = i < n && emits_ray[i] != 0u;
    tsdf_detail::RayTally own;  // this point's ray, if it emits one
    if (i == n) ray_pieces[ray_rank[n]] = 0;  // the scan's end
    if (emits) {
      const uint32_t m = ray_rank[i];
      const uint32_t code = codes[i];
      Vec3f point = points[i];
      uint32_t count = 1;
      Rgb8 color = tsdf::color_of(colors, intensities, grey_per_intensity, i);
      if (code != tsdf::kAlonePoint) {
        const tsdf::PointBundle bundle = bundles[code];
        table.free_slot(code);
        count = bundle.count;
        if (count > 1) {
          const double scale = 1.0 / (static_cast<double>(count) * tsdf::kMergeUnitsPerMetre);
          point = Vec3f(static_cast<float>(bundle.x * scale), static_cast<float>(bundle.y * scale),
                        static_cast<float>(bundle.z * scale));
          const uint32_t half = count / 2;
          color = Rgb8{static_cast<uint8_t>((bundle.r + half) / count),
                       static_cast<uint8_t>((bundle.g + half) / count),
                       static_cast<uint8_t>((bundle.b + half) / count)};
        }
      }
      const tsdf::RaySegment ray = tsdf::make_ray(ray_parameters, point);
      merged_rays[m] = ray;
      weights[m] = static_cast<float>(count);
      ray_colors[m] = color;
      own = tsdf_detail::tally_ray(ray, count, inverse_voxel_size);
      own.rays = 1;
      ray_pieces[m] = tsdf::ray_piece_count(static_cast<uint32_t>(own.voxels));
      if (ray.kind > tsdf::kClearingRay) {  // rare: a bundle's mean point dropped (closer than min_ray_length_m)
        atomic_add(&stripes[tsdf::merge_tally_stripe(i)].kinds[ray.kind], static_cast<uint64_t>(count));
      }
    }
    // The warp's rays summed, then one atomic per counter (a warp's counts fit in 32 bits).
    if (!kTallyWithAtomics || warp_ballot(lanes, emits) == 0u) return;
    const auto sum32 = [lanes](int64_t value) { return warp_sum(lanes, static_cast<uint32_t>(value)); };
    const uint32_t surface_points = sum32(own.kinds[tsdf::kSurfaceRay]);
    const uint32_t clearing_rays = sum32(own.kinds[tsdf::kClearingRay]);
    const uint32_t rays = sum32(own.rays);
    const uint32_t cast = sum32(own.cast);
    const uint32_t visits = sum32(own.voxels);
    const int32_t box[6] = {warp_min(lanes, own.low[0]),  warp_min(lanes, own.low[1]),  warp_min(lanes, own.low[2]),
                            warp_max(lanes, own.high[0]), warp_max(lanes, own.high[1]), warp_max(lanes, own.high[2])};
    if (warp_lane() != warp_first_lane(lanes)) return;
    tsdf::MergeTallyStripe& stripe = stripes[tsdf::merge_tally_stripe(i)];
    atomic_add(&stripe.kinds[tsdf::kSurfaceRay], static_cast<uint64_t>(surface_points));
    if (clearing_rays != 0u) atomic_add(&stripe.kinds[tsdf::kClearingRay], static_cast<uint64_t>(clearing_rays));
    atomic_add(&stripe.cast, static_cast<uint64_t>(cast));
    atomic_add(&stripe.rays, static_cast<uint64_t>(rays));
    atomic_add(&stripe.voxels, static_cast<uint64_t>(visits));
    for (int axis = 0; axis < 3; ++axis) {
      atomic_min(&stripe.low[axis], box[axis]);
      atomic_max(&stripe.high[axis], box[3 + axis]);
    }
  });
  scratch.merge_table_clean = true;
  profile.mark("rays");
  tsdf::MergeTally host;
  copy_bytes(&host, Device::kCpu, stripes, scratch.merge_tally.device(), sizeof(host), stream);
  reset_tally();  // for the next frame
  scratch.merge_tally_clean = true;
  tsdf_detail::RayTally tally;
  for (const tsdf::MergeTallyStripe& stripe : host.stripes) {
    tsdf_detail::RayTally part;
    for (int k = 0; k < 6; ++k) part.kinds[k] = static_cast<int64_t>(stripe.kinds[k]);
    part.cast = static_cast<int64_t>(stripe.cast);
    part.rays = static_cast<int64_t>(stripe.rays);
    part.voxels = static_cast<int64_t>(stripe.voxels);
    for (int axis = 0; axis < 3; ++axis) {
      part.low[axis] = stripe.low[axis];
      part.high[axis] = stripe.high[axis];
    }
    tally = tsdf_detail::AddTallies{}(tally, part);
  }
  if constexpr (!kTallyWithAtomics) {
    // The rays' part of the tally (the counters hold the dropped points' only).
    const int64_t ray_count = ray_rank[n];  // host memory on the CPU twin
    const tsdf_detail::RayTally rays_tally = transform_reduce(
        backend, stream, thrust::make_counting_iterator<int64_t>(0), ray_count,
        [=](int64_t m) {
          const tsdf::RaySegment& ray = merged_rays[m];
          tsdf_detail::RayTally own = tsdf_detail::tally_ray(ray, static_cast<int64_t>(weights[m]), inverse_voxel_size);
          if (ray.kind > tsdf::kClearingRay) own.kinds[ray.kind] = 0;  // counted by the kernel's atomic
          own.rays = 1;
          return own;
        },
        tsdf_detail::RayTally{}, tsdf_detail::AddTallies{});
    tally = tsdf_detail::AddTallies{}(tally, rays_tally);
  }
  profile.mark("tally");
  return tally;
}

// Steps 2b to 5 of a frame (see tsdf_integrate_points): traverse the ray pieces into one visit
// record per voxel visit, group the records by voxel (radix sort), allocate the blocks, then sum
// each voxel's records and write the voxel once (consume_run_sums: the sums go from registers to
// the map). ValueT is the records' value (tsdf_traverse.h): tsdf::DistanceUpdate without colour,
// summed as it is; tsdf::ColorVisit with colour, whose update (a tsdf::VoxelUpdate, with the
// ray's colour) is computed from its ray and voxel as the sum reads it.
template <class KeyT, class ValueT, class Backend>
void tsdf_fuse_updates(Backend backend, const TsdfIntegratorConfig& config, const tsdf::FrameUpdates& frame,
                       TsdfMap& map, TsdfScratchBuffers& scratch, IntegrationStats& stats, StageProfiler::Scope& profile,
                       const Stream& stream) {
  constexpr bool kColored = std::is_same<ValueT, tsdf::ColorVisit>::value;
  using SumT = std::conditional_t<kColored, tsdf::VoxelUpdate, tsdf::DistanceUpdate>;
  const tsdf::FrameKeyCodec codec = frame.codec;
  const int64_t total_updates = frame.total_updates;
  const float truncation = config.truncation_distance_m;
  // Keys are 32-bit when the frame's box allows (almost always): half the key bytes through the
  // traverse's writes, every radix pass and the reduction.
  auto key_buffers = scratch.update_key_buffers<KeyT>();
  for (int k = 0; k < 2; ++k) key_buffers[k]->resize_discard(total_updates);
  KeyT* keys = key_buffers[0]->data();
  KeyT* keys_alt = key_buffers[1]->data();
  const KeyT zero_weight_key = static_cast<KeyT>(codec.zero_weight_key);
  const KeyT out_of_range_key = static_cast<KeyT>(codec.out_of_range_key);
  auto value_buffers = scratch.record_value_buffers<ValueT>();
  for (Buffer<ValueT>* buffer : value_buffers) buffer->resize_discard(total_updates);
  ValueT* values = value_buffers[0]->data();
  ValueT* values_alt = value_buffers[1]->data();
  const tsdf::PieceTraversal<KeyT, ValueT> traversal{frame, zero_weight_key, scratch.piece_offsets.data(), truncation};
  tsdf::traverse_pieces(backend, stream, frame.piece_bound, total_updates, traversal,
                        tsdf::RecordArrays<KeyT, ValueT>{keys, values});

  profile.mark("2b traverse");

  // 3. group by voxel (a stable sort keeps each voxel's records in ray order, so the float sums
  //    are the same every run). The records to sum are then the sorted ones, or on the CPU twin
  //    one merged record per voxel.
  scratch.readback.resize_discard(8);
  uint32_t* counts_on_device = scratch.readback.data();
  const KeyT* record_keys = keys;
  SumT* merged_updates = nullptr;  // the CPU twin's merged records' sums
  bool grouped = false;
  if constexpr (std::is_same<Backend, CpuBackend>::value) {
    // The CPU twin groups by block and sums in dense per-block arrays (tsdf_group_updates_cpu.h):
    // the same voxels and (within rounding) sums as the sort and run sums below, with a third of
    // the moves. Its merged records are runs of one.
    if (tsdf::dense_grouping_fits(codec)) {
      key_buffers[2]->resize_discard(total_updates);
      KeyT* merged_keys = key_buffers[2]->data();
      tsdf::GroupCounts grouping;
      if constexpr (kColored) {
        scratch.merged_updates.resize_discard(total_updates);
        merged_updates = scratch.merged_updates.data();
        const tsdf::VoxelUpdateOfRecord<KeyT> update_of{frame, keys_alt, values_alt, out_of_range_key, truncation};
        grouping = tsdf::group_updates_by_voxel_cpu(codec, keys, values, total_updates, keys_alt, values_alt,
                                                    merged_keys, merged_updates, update_of, tsdf::MergeUpdates());
      } else {
        merged_updates = values;  // free once the records have moved
        const ValueT* moved = values_alt;
        grouping = tsdf::group_updates_by_voxel_cpu(
            codec, keys, values, total_updates, keys_alt, values_alt, merged_keys, merged_updates,
            [moved](int64_t j) { return moved[j]; }, tsdf::MergeUpdates());
      }
      record_keys = merged_keys;
      counts_on_device[0] = grouping.voxels;
      counts_on_device[1] = grouping.zero_weight;
      counts_on_device[2] = grouping.out_of_range;
      counts_on_device[3] = grouping.voxels;
      grouped = true;
      profile.mark("3 group by voxel");
    }
  }
  if (!grouped) {
    radix_sort_pairs_swapping(backend, stream, keys, values, total_updates, codec.key_bits, keys_alt, values_alt);
    record_keys = keys;
    // Records to drop (outside the key range, zero weight) sort last, in one run per kind
    // present: the block flags' kernel below counts them ([1]: at or past the first zero-weight
    // key, [2]: at or past the first out-of-range key; none: 0); step 5 counts the distinct
    // voxels ([7]).
    set_bytes(counts_on_device + 1, scratch.readback.device(), 0, 7 * sizeof(uint32_t), stream);
    profile.mark("3 sort records");
  }

  // 4. allocate the distinct blocks of the touched voxels in one batch. Records are sorted
  //    block-major, so each block's records form one run: the run's first record names the block
  //    and a scan ranks the runs. The hash table sees a few hundred blocks, not one key per record.
  //    On the GPU each read-back is a wait, so the flags and their scan run over the bound
  //    total_updates (no flag past the kept records, whose count stays on the device) and the
  //    counts come back in one copy; on the CPU a read-back is free and the exact count scans less.
  //    Without the CPU's grouping the counts of dropped records are found here: the same
  //    kernels, no extra launch.
  const bool counts_known = grouped;
  const bool read_back_is_free = Backend::kDevice == Device::kCpu;
  const int64_t flag_bound =
      read_back_is_free && counts_known ? tsdf_detail::read_back<4>(scratch, stream)[0] : total_updates;
  scratch.block_flags.resize_discard(flag_bound + 1);
  scratch.block_ranks.resize_discard(flag_bound + 1);
  scratch.block_indices.resize_discard(flag_bound + 1);
  uint32_t* block_flags = scratch.block_flags.data();
  uint32_t* block_ranks = scratch.block_ranks.data();
  Index3D* block_indices = scratch.block_indices.data();
  parallel_for(backend, stream, flag_bound + 1, [=] COVOX_HD(int64_t v) {
    // records past the kept ones: the dropped kinds' runs (last), then nothing written
    const bool kept = counts_known ? v < flag_bound : v < total_updates && record_keys[v] < out_of_range_key;
    block_flags[v] =
        kept && (v == 0 || codec.block_part(record_keys[v]) != codec.block_part(record_keys[v - 1])) ? 1u : 0u;
    if (counts_known || v >= total_updates) return;
    const KeyT key = record_keys[v];
    const KeyT previous = v > 0 ? record_keys[v - 1] : KeyT(0);
    if (key >= zero_weight_key && (v == 0 || previous < zero_weight_key)) {
      counts_on_device[1] = static_cast<uint32_t>(total_updates - v);
    }
    if (key >= out_of_range_key && (v == 0 || previous < out_of_range_key)) {
      counts_on_device[2] = static_cast<uint32_t>(total_updates - v);
    }
  });
  exclusive_scan(backend, stream, static_cast<const uint32_t*>(block_flags), flag_bound + 1, block_ranks);
  // Each block's index at its rank; the counts completed by one thread.
  parallel_for(backend, stream, flag_bound + 1, [=] COVOX_HD(int64_t v) {
    if (block_flags[v]) block_indices[block_ranks[v]] = codec.block(record_keys[v]);
    if (v != 0) return;
    if (!counts_known) {
      const uint32_t zero_weight = counts_on_device[1];
      const uint32_t dropped = counts_on_device[2];  // out of range and zero weight
      counts_on_device[2] = dropped - zero_weight;
      counts_on_device[0] = static_cast<uint32_t>(total_updates) - dropped;
    }
    counts_on_device[4] = block_ranks[counts_on_device[0]];
  });
  // On the GPU the blocks' activation is queued before that read-back, for the blocks counted on
  // the device (at most one per flagged record and per block of the frame's box), and its totals
  // come back with the frame's counts: one wait instead of two. When the table might have to grow
  // it needs the exact count first (activate_queued says no), and on the CPU waiting costs nothing.
  bool queued = false;
  if (!read_back_is_free) {
    const int64_t box_blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
    const int64_t block_bound = std::min<int64_t>(flag_bound, box_blocks);
    scratch.slots.resize_discard(block_bound);
    scratch.is_new.resize_discard(block_bound);
    queued = map.blocks().activate_queued(block_indices, counts_on_device + 4, block_bound, scratch.slots.data(),
                                          scratch.is_new.data(), counts_on_device + 5, stream);
  }
  const std::array<uint32_t, 7> counts = tsdf_detail::read_back<7>(scratch, stream);
  const int64_t record_count = counts[0];  // kept records (sorted), or merged voxels (grouped)
  stats.voxels_out_of_range = counts[2];
  const int64_t block_count = counts[4];
  profile.mark("4a distinct blocks");
  ActivateResult activation;
  if (queued) activation = map.blocks().finish_queued_activation(counts[5], counts[6], stream);
  if (record_count == 0) return;
  if (!queued) {
    scratch.slots.resize_discard(block_count);
    scratch.is_new.resize_discard(block_count);
    activation = map.blocks().activate(block_indices, block_count, scratch.slots.data(), scratch.is_new.data(), stream);
  }
  stats.blocks_allocated = activation.num_new;
  profile.mark("4b hash activate");
  map.ensure_pool_capacity(stream);
  profile.mark("4c pool capacity");
  const uint32_t* slots = scratch.slots.data();
  if (activation.num_out_of_range + activation.num_failed_full > 0) {
    // Rare: count the voxels whose block the hash table rejected (outside its key range, or full).
    scratch.counts.resize_discard(record_count);
    uint32_t* rejected = scratch.counts.data();
    parallel_for(backend, stream, record_count, [=] COVOX_HD(int64_t j) {
      const bool voxel_start = j == 0 || record_keys[j] != record_keys[j - 1];
      rejected[j] = voxel_start && slots[block_ranks[j] + block_flags[j] - 1] == kInvalidSlot ? 1u : 0u;
    });
    stats.voxels_out_of_range += count_if(backend, stream, rejected, record_count, [] COVOX_HD(uint32_t r) { return r != 0; });
  }

  // Clear new blocks: a new block may reuse the slot of an erased one. (The voxel writes below
  // mark the blocks changed, for the ESDF and the mesh.)
  auto tsdf_view = map.tsdf().view();
  auto color_view = map.color().view();
  uint8_t* block_changed = map.block_changed().data();
  auto esdf_view = map.esdf().view();
  const uint8_t* is_new = scratch.is_new.data();
  const int64_t voxels_per_block = map.voxels_per_block();
  if (activation.num_new > 0) {
    parallel_for(backend, stream, block_count * voxels_per_block, [=] COVOX_HD(int64_t i) {
      const int64_t b = i / voxels_per_block;
      if (!is_new[b] || slots[b] == kInvalidSlot) return;
      const int64_t index = static_cast<int64_t>(slots[b]) * voxels_per_block + i % voxels_per_block;
      tsdf_view.store(index, TsdfVoxel{});
      color_view.store(index, ColorVoxel{});
      esdf_view.store(index, EsdfVoxel{});
    });
  }

  profile.mark("4d clear new blocks");

  // 5. each voxel's records summed and written once: a weighted average with the voxel, given
  //    the index of the voxel's first record and the sum of its updates
  const float max_weight = config.max_weight;
  const auto write_voxel = [=] COVOX_HD(int64_t j, const SumT& update) {
    const uint32_t slot = slots[block_ranks[j] + block_flags[j] - 1];  // the rank of j's block
    if (slot == kInvalidSlot) return;
    if (block_flags[j]) block_changed[slot] = kAllPending;  // once per block: its first voxel
    if (update.weight <= 0.0f) return;
    const int64_t index = static_cast<int64_t>(slot) * voxels_per_block + codec.voxel_in_block(record_keys[j]);
    TsdfVoxel voxel = tsdf_view.load(index);
    const float combined = voxel.weight + update.weight;
    float distance = (voxel.distance_m * voxel.weight + update.weighted_distance) / combined;
    distance = distance > truncation ? truncation : (distance < -truncation ? -truncation : distance);
    voxel.distance_m = distance;
    voxel.weight = combined < max_weight ? combined : max_weight;
    tsdf_view.store(index, voxel);
    tsdf_detail::blend_color(color_view, index, update, max_weight);
  };
  if (grouped) {  // one record per voxel: the count is known
    consume_run_sums<SumT>(backend, stream, record_keys, record_count, tsdf_detail::ArrayTerm<SumT>{merged_updates},
                           tsdf::MergeUpdates(), write_voxel, scratch.run_tile_parts);
    stats.voxels_updated = counts[3];
    stream.synchronize();
  } else {
    uint32_t* voxels_counted = counts_on_device + 7;
    if constexpr (kColored) {
      const tsdf::VoxelUpdateOfRecord<KeyT> update_of{frame, keys, values, out_of_range_key, truncation};
      consume_run_sums<SumT>(backend, stream, record_keys, record_count, update_of, tsdf::MergeUpdates(), write_voxel,
                             scratch.run_tile_parts, voxels_counted);
    } else {
      consume_run_sums<SumT>(backend, stream, record_keys, record_count, tsdf_detail::ArrayTerm<SumT>{values},
                             tsdf::MergeUpdates(), write_voxel, scratch.run_tile_parts, voxels_counted);
    }
    stats.voxels_updated = tsdf_detail::read_back<8>(scratch, stream)[7];  // waits for the writes too
  }
  profile.mark("5 sum and write voxels");
}

template <class Backend>
IntegrationStats tsdf_integrate_points(Backend backend, const TsdfIntegratorConfig& config,
                                       TsdfMap& map, const PointCloudView& cloud,
                                       const Eigen::Isometry3d& T_map_sensor,
                                       TsdfScratchBuffers& scratch, const Stream& stream) {
  IntegrationStats stats;
  const int64_t n = cloud.count;
  stats.points_in = n;
  if (n == 0) return stats;
  StageProfiler::Scope profile("tsdf", stream);

  const float voxel_size = map.voxel_size_m();
  const float inverse_voxel_size = 1.0f / voxel_size;
  const int32_t voxels_per_side = map.voxels_per_side();
  const tsdf::RayParameters ray_parameters{to_transform3f(T_map_sensor),
                                           voxel_size,
                                           config.truncation_distance_m,
                                           config.min_ray_length_m,
                                           config.max_ray_length_m,
                                           config.voxel_carving_enabled,
                                           config.allow_clear};
  const tsdf::WeightParameters weight_parameters{voxel_size,
                                                 config.truncation_distance_m,
                                                 config.use_const_weight,
                                                 config.use_weight_dropoff,
                                                 config.use_sparsity_compensation_factor,
                                                 config.sparsity_compensation_factor};

  // 1. rays: one per point, or one per bundle of points whose surface falls into one voxel.
  //    What each ray carries into the update: per-point colour or intensity, or per-bundle colour
  //    and weight after merging.
  const Vec3f* points = cloud.points;
  const Rgb8* colors = config.integrate_color ? cloud.colors : nullptr;
  const float* intensities = config.integrate_color && !colors ? cloud.intensities : nullptr;
  const float grey_per_intensity = 255.0f / cloud.intensity_max_value;
  const bool has_color = colors || intensities;
  const float* ray_weights = nullptr;
  int64_t ray_count = n;
  tsdf_detail::RayTally tally;
  if (config.method != TsdfIntegrationMethod::kMerged) {
    // Why points did or did not become rays, and the box of voxels their own rays traverse.
    tally = transform_reduce(backend, stream, points, n, tsdf_detail::TallyPoint{ray_parameters, inverse_voxel_size},
                             tsdf_detail::RayTally{}, tsdf_detail::AddTallies{});
    profile.mark("1 rays + tally");
    scratch.rays.resize_discard(n);
    scratch.counts.resize_discard(n + 1);
    tsdf::RaySegment* point_rays = scratch.rays.data();
    uint32_t* ray_pieces = scratch.counts.data();
    parallel_for(backend, stream, n + 1, [=] COVOX_HD(int64_t i) {
      if (i == n) {
        ray_pieces[n] = 0;  // the scan's end
        return;
      }
      const tsdf::RaySegment ray = tsdf::make_ray(ray_parameters, points[i]);
      point_rays[i] = ray;
      ray_pieces[i] = tsdf::ray_piece_count(tsdf::ray_voxel_count(ray, inverse_voxel_size));
    });
  } else {
    // Merge keys from a box around the sensor (no pass over the points first); the merge table
    // hashes them, so their length costs nothing.
    const tsdf::MergeKeys merge_keys = tsdf::make_merge_keys(ray_parameters.T_world_sensor.translation,
                                                             config.max_ray_length_m, voxel_size, voxels_per_side);
    tally = tsdf_merge_rays(backend, ray_parameters, merge_keys, cloud, colors, intensities, grey_per_intensity,
                            scratch, stream);
    ray_weights = scratch.ray_weights.data();
    colors = has_color ? scratch.ray_colors.data() : nullptr;
    intensities = nullptr;
    ray_count = tally.rays;
    profile.mark("1 merge rays + tally");
  }
  stats.surface_rays = tally.kinds[tsdf::kSurfaceRay];
  stats.clearing_rays = tally.kinds[tsdf::kClearingRay];
  stats.dropped_non_finite = tally.kinds[tsdf::kDroppedNonFinite];
  stats.dropped_zero = tally.kinds[tsdf::kDroppedZero];
  stats.dropped_too_close = tally.kinds[tsdf::kDroppedTooClose];
  stats.dropped_too_far = tally.kinds[tsdf::kDroppedTooFar];
  stats.rays_cast = tally.cast;

  // 2. one update per traversed voxel, walked in ray pieces (tsdf_kernels.h: one thread per
  //    piece of ~8 voxels rather than per ray). Pieces per ray -> each ray's first piece; the
  //    piece table; voxels per piece -> each piece's range in the update array.
  const int64_t total_updates = tally.voxels;
  stats.voxel_updates = total_updates;
  if (total_updates == 0) return stats;
  const tsdf::FrameKeyCodec codec = tsdf::make_frame_key_codec(tally.low_voxel(), tally.high_voxel(), voxels_per_side);
  // Every ray has at most voxels / kVoxelsPerPiece + 1 pieces: a bound known without a read-back.
  const int64_t piece_bound = total_updates / tsdf::kVoxelsPerPiece + ray_count;
  // (each ray's piece count was written with the ray, and a 0 after the last ray)
  scratch.offsets.resize_discard(ray_count + 1);
  tsdf::RaySegment* rays = scratch.rays.data();
  const uint32_t* ray_pieces = scratch.counts.data();
  exclusive_scan(backend, stream, ray_pieces, ray_count + 1, scratch.offsets.data());
  const uint32_t* first_piece = scratch.offsets.data();
  const uint32_t* piece_total = first_piece + ray_count;  // on the device
  scratch.pieces.resize_discard(piece_bound);
  scratch.piece_voxels.resize_discard(piece_bound);
  scratch.piece_offsets.resize_discard(piece_bound);
  tsdf::RayPiece* pieces = scratch.pieces.data();
  uint32_t* piece_voxels = scratch.piece_voxels.data();
  // The piece table (each piece's ray and index) and each piece's voxel count; the counts past
  // the last piece are zeroed for the scan over the bound.
  const Index3D* piece_first_voxels = nullptr;
  if constexpr (Backend::kDevice == Device::kCpu) {
    // One ray per iteration, its cuts in order: each cut voxel computed once (it ends one piece
    // and starts the next) and kept for the traverse, which then computes none (2-core CPU,
    // OS1-64 scan: this step 7 -> 3 ms, the traverse -10 %). Thread i also zeroes the i-th count
    // past the last piece: there are at most ray_count of them (piece_bound - ray_count is at
    // most the pieces' total voxels / kVoxelsPerPiece).
    scratch.piece_first_voxels.resize_discard(piece_bound);
    Index3D* firsts = scratch.piece_first_voxels.data();
    piece_first_voxels = firsts;
    parallel_for(backend, stream, ray_count, [=](int64_t i) {
      if (*piece_total + i < piece_bound) piece_voxels[*piece_total + i] = 0;
      const uint32_t count = ray_pieces[i];
      tsdf::for_each_ray_piece(rays[i], count, inverse_voxel_size, [&](uint32_t k, const Index3D& first, uint32_t voxels) {
        const uint32_t p = first_piece[i] + k;
        pieces[p] = tsdf::RayPiece{static_cast<uint32_t>(i), k, count};
        firsts[p] = first;
        piece_voxels[p] = voxels;
      });
    });
  } else {
    // Not on the GPU, where both versions tried cost more than they saved (H100, KITTI 50 m
    // rays of about 30 pieces, this step 85-92 -> 140-145 us per scan): the loop over a ray's
    // cuts serialises long rays, and a piece table carrying the cut voxels doubles its strided
    // writes. One thread per piece instead: it finds its ray by a binary search of the rays'
    // first pieces (a few kilobytes, cached), writes its table entry and counts its own voxels;
    // the traverse computes the cuts again. (A loop per ray listing its pieces, then a kernel
    // per piece: 15 us more per 7-Scenes 5 cm frame, H100, 2026-11-24.)
    parallel_for(backend, stream, piece_bound, [=] COVOX_HD(int64_t p) {
      if (p >= *piece_total) {
        piece_voxels[p] = 0;
        return;
      }
      const uint32_t piece = static_cast<uint32_t>(p);
      // the last ray whose first piece is at or before p (rays without pieces share the next one's)
      const uint32_t i = static_cast<uint32_t>(lower_bound_index(first_piece, ray_count, piece + 1u) - 1);
      const uint32_t index = piece - first_piece[i];
      const uint32_t count = ray_pieces[i];
      pieces[p] = tsdf::RayPiece{i, index, count};
      piece_voxels[p] = tsdf::ray_piece_voxel_count(rays[i], index, count, inverse_voxel_size);
    });
  }
  exclusive_scan(backend, stream, piece_voxels, piece_bound, scratch.piece_offsets.data());
  profile.mark("2a ray pieces");

  const tsdf::FrameUpdates frame{codec,
                                  total_updates,
                                  piece_bound,
                                  piece_total,
                                  pieces,
                                  piece_first_voxels,
                                  rays,
                                  colors,
                                  intensities,
                                  grey_per_intensity,
                                  ray_weights,
                                  inverse_voxel_size,
                                  voxel_size,
                                  weight_parameters};
  const bool short_keys = codec.key_bits <= 32;
  if (has_color && short_keys) {
    tsdf_fuse_updates<uint32_t, tsdf::ColorVisit>(backend, config, frame, map, scratch, stats, profile, stream);
  } else if (has_color) {
    tsdf_fuse_updates<uint64_t, tsdf::ColorVisit>(backend, config, frame, map, scratch, stats, profile, stream);
  } else if (short_keys) {
    tsdf_fuse_updates<uint32_t, tsdf::DistanceUpdate>(backend, config, frame, map, scratch, stats, profile, stream);
  } else {
    tsdf_fuse_updates<uint64_t, tsdf::DistanceUpdate>(backend, config, frame, map, scratch, stats, profile, stream);
  }
  return stats;
}

template <class Backend>
void tsdf_unproject_depth(Backend backend, const DepthImageView& image, TsdfScratchBuffers& scratch,
                          const Stream& stream) {
  const PinholeIntrinsics k = image.intrinsics;
  const int64_t pixels = static_cast<int64_t>(k.width) * k.height;
  scratch.points.resize_discard(pixels);
  Vec3f* points = scratch.points.data();
  const uint16_t* depth = image.depth;
  const float* depth_m = image.depth_m;
  const float metres_per_unit = 1.0f / image.depth_units_per_m;
  const uint16_t invalid = image.invalid_value;
  const float inverse_fx = 1.0f / k.fx, inverse_fy = 1.0f / k.fy;
  parallel_for(backend, stream, pixels, [=] COVOX_HD(int64_t p) {
    float z = 0.0f;
    if (depth_m) {
      z = depth_m[p];
      if (!(z > 0.0f) || !(z < 3.0e38f)) z = 0.0f;  // NaN, Inf, 0 or negative: no measurement
    } else {
      const uint16_t raw = depth[p];
      z = (raw == 0 || raw == invalid) ? 0.0f : raw * metres_per_unit;
    }
    if (z == 0.0f) {
      points[p] = Vec3f(0.0f, 0.0f, 0.0f);  // dropped (and counted) as a zero point
      return;
    }
    const float u = static_cast<float>(p % k.width), v = static_cast<float>(p / k.width);
    points[p] = Vec3f((u - k.cx) * z * inverse_fx, (v - k.cy) * z * inverse_fy, z);
  });
}

#define COVOX_INSTANTIATE_TSDF_INTEGRATOR(Backend)                                                  \
  template IntegrationStats tsdf_integrate_points<Backend>(                                         \
      Backend, const TsdfIntegratorConfig&, TsdfMap&, const PointCloudView&,                        \
      const Eigen::Isometry3d&, TsdfScratchBuffers&, const Stream&);                                \
  template void tsdf_unproject_depth<Backend>(Backend, const DepthImageView&, TsdfScratchBuffers&,  \
                                              const Stream&);

}  // namespace covox

#pragma once
// Stage 1 of a merged TSDF frame: points bundled by the voxel their surface falls into, one ray
// per bundle and per point that stays alone (tsdf_ray_merging.h), and the frame's tally.
#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>

#include <thrust/iterator/counting_iterator.h>

#include "covoxslam/core/error.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/core/warp_reduce.h"
#include "covoxslam/integrators/internal/tsdf_frame_plan.h"
#include "covoxslam/integrators/internal/tsdf_ray_tally.h"
#include "covoxslam/integrators/internal/tsdf_ray_merging.h"

namespace covox::integrators::tsdf {

// Frees one slot of the merge table.
struct FreeMergeSlot {
  MergeTable table;
  COVOX_HD_INLINE void operator()(int64_t slot) const {
    table.free_slot(static_cast<uint32_t>(slot));
  }
};

// The merge table for a frame of n points: at least twice n slots (a power of two), all free.
// A frame frees the slots it used (WriteMergedRays), so the table is cleared only when it grows
// or when the last frame did not get that far (an exception between its kernels).
template <class Backend>
MergeTable clean_merge_table(Backend backend, TsdfScratchBuffers::Merge& merge, int64_t n,
                             const Stream& stream) {
  int log2_capacity = 10;
  while ((int64_t(1) << log2_capacity) < 2 * n) ++log2_capacity;
  const int64_t capacity = int64_t(1) << log2_capacity;
  if (log2_capacity > 31)
    throw Error("TSDF integrator: " + std::to_string(n) +
                " points in one frame are too many to merge");
  if (static_cast<int64_t>(merge.table_keys.size()) < capacity || !merge.table_clean) {
    const int64_t size = std::max<int64_t>(capacity, static_cast<int64_t>(merge.table_keys.size()));
    merge.table_keys.resize_discard(size);
    merge.table_bundles.resize_discard(size);
    const MergeTable all{merge.table_keys.data(), merge.table_bundles.data(), 0u, 0};
    parallel_for(backend, stream, size, FreeMergeSlot{all});
  }
  merge.table_clean = false;  // until the frame's last merge kernel has freed its slots
  return MergeTable{merge.table_keys.data(), merge.table_bundles.data(),
                    static_cast<uint32_t>(capacity - 1), 64 - log2_capacity};
}

// Clears the merge's tally for the next frame. A frame does it at its end, where the host has
// queued everything and waits for the device anyway, rather than just before its merge, where
// the device would wait for this launch. A frame whose last kernel is the pass over the listed
// blocks' cells has that kernel do it (one launch fewer): merge_tally_to_reset() hands it the
// stripes, or null when there is nothing to do.
inline MergeTallyStripe* merge_tally_to_reset(TsdfScratchBuffers::Merge& merge) {
  return merge.tally.size() != 1 || merge.tally_clean ? nullptr : merge.tally.data()->stripes;
}
struct ResetMergeTally {
  MergeTallyStripe* stripes;
  COVOX_HD_INLINE void operator()(int64_t k) const { stripes[k].reset(); }
};
template <class Backend>
void reset_merge_tally(Backend backend, TsdfScratchBuffers::Merge& merge, const Stream& stream) {
  MergeTallyStripe* stripes = merge_tally_to_reset(merge);
  if (!stripes) return;
  parallel_for(backend, stream, kMergeTallyStripes, ResetMergeTally{stripes});
  merge.tally_clean = true;
}

// Every point: its ray, its bundle (claimed or found in the table), its sums added. A warp's
// points of one bundle add their sums together, one atomic per field (warp_reduce.h): a voxel of
// a depth image holds many pixels, whose atomics would otherwise queue up. Each group of a warp's
// lanes reduces in turn, so the reductions are few: the count and the first point come from the
// group's mask (the lanes of a warp hold consecutive points), two colour channels share a word (a
// sum of 32 is at most 8160). Reading a depth image, the point (and its colour) is unprojected
// here and written for the ray kernel.
struct BundlePoints {
  RayParameters ray_parameters;
  MergeKeys merge_keys;
  MergeTable table;
  MergeTallyStripe* stripes;
  uint32_t* codes;
  const Vec3f* points;
  const Rgb8* colors;
  const float* intensities;
  float grey_per_intensity;
  float inverse_voxel_size;
  bool has_color;
  // Points of one voxel lie within 2^31 merge units of each other (per axis) when the voxel's
  // diagonal is under about 1.8 m: their coordinates sum in two warp reductions each instead of
  // four (warp_sum_clustered).
  bool clustered;
  bool reads_image;
  DepthImagePoints image;
  Vec3f* image_points;
  Rgb8* image_colors;

  COVOX_HD_INLINE void read_point(int64_t i, Vec3f* point, Rgb8* color) const {
    if (reads_image) {  // the same for every point
      const int64_t pixel = image.pixel_at(i);
      *point = image.point(pixel);
      image_points[i] = *point;
      *color = image_colors ? image.colors[pixel] : Rgb8{};
      if (image_colors) image_colors[i] = *color;
    } else {
      *point = points[i];
      *color = color_of(colors, intensities, grey_per_intensity, i);
    }
  }
  // The bundle's sums over the warp's `peers`, added by their leader; its slot, for every peer.
  COVOX_HD_INLINE uint32_t add_to_bundle(int64_t i, uint64_t key, uint32_t peers, int leader,
                                         const Vec3f& point, const Rgb8& color) const {
    PointBundle sums;
    const bool clustered_sums = clustered;
    const auto sum_units = [peers, clustered_sums](float metres) {
      const int64_t units = to_merge_units(metres);
      return clustered_sums ? warp_sum_clustered(peers, units)
                            : static_cast<int64_t>(warp_sum(peers, static_cast<uint64_t>(units)));
    };
    sums.x = sum_units(point.x);
    sums.y = sum_units(point.y);
    sums.z = sum_units(point.z);
    if (has_color) {
      const uint32_t red_green =
          warp_sum(peers, static_cast<uint32_t>(color.r) | (static_cast<uint32_t>(color.g) << 16));
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
    return warp_broadcast(peers, slot, leader);
  }
  COVOX_HD_INLINE void operator()(int64_t i) const {
    const uint32_t lanes = warp_lanes();
    Vec3f point;
    Rgb8 color;
    read_point(i, &point, &color);
    uint64_t key = 0;
    uint32_t code = merge_keys.classify(make_ray(ray_parameters, point), inverse_voxel_size, &key);
    if (code != 0u) key = kFreeMergeKey;  // no bundle
    // The warp's points of one bundle (equal keys) reduce among themselves, all bundles at once.
    const uint32_t peers = warp_match(lanes, key);
    const int leader = warp_first_lane(peers);
    if (key != kFreeMergeKey) code = add_to_bundle(i, key, peers, leader, point, color);
    codes[i] = code;
    // Dropped points are only counted, per warp.
    if (warp_ballot(lanes, is_dropped_code(code)) == 0u) return;
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t dropped = warp_sum(lanes, code == kDroppedPointCode + k ? 1u : 0u);
      if (dropped != 0u && warp_lane() == warp_first_lane(lanes)) {
        atomic_add(&stripes[merge_tally_stripe(i)].kinds[kDroppedNonFinite + k],
                   static_cast<uint64_t>(dropped));
      }
    }
  }
};

// The points that emit a ray: a point alone, or the first point of its bundle. Point n (one past
// the last) emits none; its rank is the count of rays.
struct EmitsRay {
  const uint32_t* codes;
  const PointBundle* bundles;
  int64_t n;
  COVOX_HD_INLINE uint32_t operator()(int64_t i) const {
    if (i == n) return 0u;
    const uint32_t code = codes[i];
    return code == kAlonePoint ||
                   (is_bundle_slot(code) && bundles[code].first == static_cast<uint32_t>(i))
               ? 1u
               : 0u;
  }
};
// The scan's output: each emitting point listed at its rank, the count of rays after them.
struct ListEmittingPoint {
  EmitsRay emits_ray;
  uint32_t* ray_points;
  COVOX_HD_INLINE void operator()(int64_t i, uint32_t rank) const {
    if (i == emits_ray.n) {
      ray_points[emits_ray.n] = rank;
    } else if (emits_ray(i) != 0u) {
      ray_points[rank] = static_cast<uint32_t>(i);
    }
  }
};

// Each ray (thread m < the count) written from its point, its bundle's slot freed (the table is
// clean again) and, with kTallyWithAtomics (the GPU), the ray added to the tally, per warp; thread
// m == count writes the piece counts' end, and the threads past it leave. On the CPU twin a
// "warp" is one call, so the tally's atomics would be one per ray and counter, on lines every core
// writes: there the rays are tallied by a reduction afterwards instead (MergedRayTally).
template <bool kTallyWithAtomics>
struct WriteMergedRays {
  RayParameters ray_parameters;
  MergeTable table;
  const PointBundle* bundles;
  MergeTallyStripe* stripes;
  const uint32_t* codes;
  const uint32_t* ray_points;
  const Vec3f* points;
  const Rgb8* colors;
  const float* intensities;
  float grey_per_intensity;
  float inverse_voxel_size;
  int64_t n;
  RaySegment* merged_rays;
  float* weights;
  Rgb8* ray_colors;
  uint32_t* ray_pieces;
  // The hand-off of the tally (GPU; MergeTallySummary): the warps done, the summary, the frame's
  // stamp.
  MergeTallySummary* summary;
  uint32_t* warps_done;
  uint32_t sequence;

  // Ray m, from its point i, and its tally.
  COVOX_HD_INLINE RayTally write_ray(int64_t m) const {
    const int64_t i = static_cast<int64_t>(ray_points[m]);
    const uint32_t code = codes[i];
    Vec3f point = points[i];
    uint32_t count = 1;
    Rgb8 color = color_of(colors, intensities, grey_per_intensity, i);
    if (code != kAlonePoint) {
      const PointBundle bundle = bundles[code];
      table.free_slot(code);
      count = bundle.count;
      if (count > 1) {
        const double scale = 1.0 / (static_cast<double>(count) * kMergeUnitsPerMetre);
        point = Vec3f(static_cast<float>(bundle.x * scale), static_cast<float>(bundle.y * scale),
                      static_cast<float>(bundle.z * scale));
        const uint32_t half = count / 2;
        color = Rgb8{static_cast<uint8_t>((bundle.r + half) / count),
                     static_cast<uint8_t>((bundle.g + half) / count),
                     static_cast<uint8_t>((bundle.b + half) / count)};
      }
    }
    const RaySegment ray = make_ray(ray_parameters, point);
    merged_rays[m] = ray;
    weights[m] = static_cast<float>(count);
    ray_colors[m] = color;
    RayTally own = tally_ray(ray, count, inverse_voxel_size);
    own.rays = 1;
    ray_pieces[m] = static_cast<uint32_t>(own.most_pieces);
    if (ray.kind > kClearingRay) {  // rare: a bundle's mean point dropped (closer than
                                    // min_ray_length_m)
      atomic_add(&stripes[merge_tally_stripe(m)].kinds[ray.kind], static_cast<uint64_t>(count));
    }
    return own;
  }
  // The warp's rays summed, then one atomic per counter (a warp's counts fit in 32 bits).
  COVOX_HD_INLINE void add_warp_tally(int64_t m, uint32_t lanes, bool leader,
                                      const RayTally& own) const {
    const auto sum32 = [lanes](int64_t value) {
      return warp_sum(lanes, static_cast<uint32_t>(value));
    };
    const uint32_t surface_points = sum32(own.kinds[kSurfaceRay]);
    const uint32_t clearing_rays = sum32(own.kinds[kClearingRay]);
    const uint32_t rays = sum32(own.rays);
    const uint32_t cast = sum32(own.cast);
    const uint32_t visits = sum32(own.voxels);
    const int32_t most_pieces = warp_max(lanes, own.most_pieces);
    const int32_t box[6] = {warp_min(lanes, own.low[0]),  warp_min(lanes, own.low[1]),
                            warp_min(lanes, own.low[2]),  warp_max(lanes, own.high[0]),
                            warp_max(lanes, own.high[1]), warp_max(lanes, own.high[2])};
    if (!leader) return;
    MergeTallyStripe& stripe = stripes[merge_tally_stripe(m)];
    atomic_add(&stripe.kinds[kSurfaceRay], static_cast<uint64_t>(surface_points));
    if (clearing_rays != 0u)
      atomic_add(&stripe.kinds[kClearingRay], static_cast<uint64_t>(clearing_rays));
    atomic_add(&stripe.cast, static_cast<uint64_t>(cast));
    atomic_add(&stripe.rays, static_cast<uint64_t>(rays));
    atomic_add(&stripe.voxels, static_cast<uint64_t>(visits));
    atomic_max(&stripe.most_pieces, most_pieces);
    for (int axis = 0; axis < 3; ++axis) {
      atomic_min(&stripe.low[axis], box[axis]);
      atomic_max(&stripe.high[axis], box[3 + axis]);
    }
  }
  // The hand-off: the warps of threads 0..ray_total count themselves done; the last one out sums
  // the stripes into the summary and stamps it.
  COVOX_HD_INLINE void hand_off(uint32_t ray_total, uint32_t lanes, bool leader) const {
    uint32_t done = 0;
    if (leader) {
      device_fence();  // this warp's atomics before its count
      done = atomic_add(warps_done, 1u);
    }
    done = warp_broadcast(lanes, done, warp_first_lane(lanes));
    if (done != ray_total / 32u) return;  // (ray_total + 1 threads: ray_total / 32 + 1 warps)
    device_fence();                       // the other warps' atomics before the stripes' reads
    const MergeTallyStripe sum = sum_merge_tally_stripes(stripes, lanes);
    if (!leader) return;
    summary->sum = sum;
    summary->sequence = sequence;
    *warps_done = 0;  // for the next frame
  }
  COVOX_HD_INLINE void operator()(int64_t m) const {
    const uint32_t ray_total = ray_points[n];
    if (m > ray_total) return;
    const uint32_t lanes = warp_lanes();
    const bool emits = m < ray_total;
    RayTally own;                           // this thread's ray, if it has one
    if (m == ray_total) ray_pieces[m] = 0;  // the end of the counts
    if (emits) own = write_ray(m);
    if (!kTallyWithAtomics) return;
    const bool leader = warp_lane() == warp_first_lane(lanes);
    if (warp_ballot(lanes, emits) != 0u) add_warp_tally(m, lanes, leader, own);
    hand_off(ray_total, lanes, leader);
  }
};

// The CPU twin's tally of the rays (the counters hold the dropped points' only).
struct MergedRayTally {
  const RaySegment* merged_rays;
  const float* weights;
  float inverse_voxel_size;
  RayTally operator()(int64_t m) const {
    const RaySegment& ray = merged_rays[m];
    RayTally own = tally_ray(ray, static_cast<int64_t>(weights[m]), inverse_voxel_size);
    if (ray.kind > kClearingRay) own.kinds[ray.kind] = 0;  // counted by the kernel's atomic
    own.rays = 1;
    return own;
  }
};

// The tally that stripes of the merge's counters hold.
inline RayTally tally_of_stripes(const MergeTallyStripe* stripes, int stripe_count) {
  RayTally tally;
  for (int k = 0; k < stripe_count; ++k) {
    const MergeTallyStripe& stripe = stripes[k];
    RayTally part;
    for (int kind = 0; kind < 6; ++kind)
      part.kinds[kind] = static_cast<int64_t>(stripe.kinds[kind]);
    part.cast = static_cast<int64_t>(stripe.cast);
    part.rays = static_cast<int64_t>(stripe.rays);
    part.voxels = static_cast<int64_t>(stripe.voxels);
    part.most_pieces = stripe.most_pieces;
    for (int axis = 0; axis < 3; ++axis) {
      part.low[axis] = stripe.low[axis];
      part.high[axis] = stripe.high[axis];
    }
    tally = AddTallies{}(tally, part);
  }
  return tally;
}

// The GPU's tally: the summary the ray kernel left in host memory, once the stream is done (no
// copy). Throws covox::Error when the summary is not this frame's.
inline RayTally collect_mapped_tally(TsdfScratchBuffers::Merge& merge, uint32_t sequence,
                                     const Stream& stream) {
  stream.synchronize();
  const auto* written = static_cast<const MergeTallySummary*>(merge.summary->host_data());
  if (written->sequence != sequence) {
    merge.warps_done.fill_bytes(0, stream);
    throw Error("TSDF integrator: the merge's tally of frame " + std::to_string(sequence) +
                " did not arrive (the summary is frame " + std::to_string(written->sequence) +
                "'s); the frame was not integrated");
  }
  return tally_of_stripes(&written->sum, 1);
}

// The CPU twin's tally: the stripes (the dropped points) and a reduction over the rays, whose
// count the scan left in host memory.
template <class Backend>
RayTally collect_reduced_tally(Backend backend, TsdfScratchBuffers& scratch, int64_t n,
                               float inverse_voxel_size, const Stream& stream) {
  MergeTally host;
  copy_bytes(&host, Device::kCpu, scratch.merge.tally.data()->stripes, scratch.merge.tally.device(),
             sizeof(host), stream);
  const RayTally dropped = tally_of_stripes(host.stripes, kMergeTallyStripes);
  const int64_t ray_count = scratch.merge.ray_points.data()[n];
  const RayTally rays = transform_reduce(
      backend, stream, thrust::make_counting_iterator<int64_t>(0), ray_count,
      MergedRayTally{scratch.rays.rays.data(), scratch.rays.weights.data(), inverse_voxel_size},
      RayTally{}, AddTallies{});
  return AddTallies{}(dropped, rays);
}

// The GPU's hand-off of the tally: the summary in mapped host memory, the warps' counter.
template <class Backend>
void prepare_tally_hand_off(TsdfScratchBuffers::Merge& merge, const Stream& stream) {
  if (!merge.summary) {
    merge.summary = std::make_unique<MappedHostBytes>(Backend::kDevice, sizeof(MergeTallySummary));
  }
  if (merge.warps_done.size() != 1) {
    merge.warps_done.resize_discard(1);
    merge.warps_done.fill_bytes(0, stream);
  }
}

// The points bundled: each point's code (its bundle's slot, kAlonePoint or a drop) in
// scratch.merge.point_codes. With a depth image, its points and colours written to scratch.input.
template <class Backend>
void bundle_points(const FrameContext<Backend>& frame, const FramePoints& points,
                   const RayParameters& ray_parameters, const MergeKeys& merge_keys,
                   const MergeTable& table) {
  TsdfScratchBuffers& scratch = frame.scratch;
  const int64_t n = points.cloud.count;
  scratch.merge.point_codes.resize_discard(n);
  const bool reads_image = points.depth_image != nullptr;
  // (reading the image: the points and colours written for the ray kernel, which `cloud` names)
  Vec3f* image_points = reads_image ? scratch.input.points.data() : nullptr;
  Rgb8* image_colors = reads_image && points.colors ? scratch.input.colors.data() : nullptr;
  if (reads_image &&
      (points.cloud.points != image_points || (points.colors && points.colors != image_colors))) {
    throw Error(
        "TSDF integrator: a depth image read in place must name the scratch points and colours "
        "(internal error)");
  }
  const BundlePoints kernel{ray_parameters,
                            merge_keys,
                            table,
                            scratch.merge.tally.data()->stripes,
                            scratch.merge.point_codes.data(),
                            points.cloud.points,
                            points.colors,
                            points.intensities,
                            points.grey_per_intensity,
                            1.0f / ray_parameters.voxel_size_m,
                            points.has_color(),
                            ray_parameters.voxel_size_m * 1.7320508f * kMergeUnitsPerMetre < 2.0e9f,
                            reads_image,
                            reads_image ? *points.depth_image : DepthImagePoints{},
                            image_points,
                            image_colors};
  parallel_for(frame.backend, frame.stream, n, kernel);
}

// The points that emit a ray, listed in point order (the same on both backends): ray m's point
// is ray_points[m], and ray_points[n] holds the count of rays. The scan of the points' flags lists
// each emitting point at its rank as the rank is known (its output reads the flag again, from
// cache), so that the ray kernel runs one thread per ray, not per point, and a warp tallies 32
// rays in one set of atomics.
template <class Backend>
void rank_rays(const FrameContext<Backend>& frame, int64_t n, const MergeTable& table) {
  TsdfScratchBuffers::Merge& merge = frame.scratch.merge;
  merge.ray_points.resize_discard(n + 1);
  const EmitsRay emits_ray{merge.point_codes.data(), table.bundles, n};
  merge.ray_scan_scratch.resize_discard(Backend::kDevice == Device::kCpu ? n + 1
                                                                         : 0);  // the CPU's only
  exclusive_scan_of<2>(frame.backend, frame.stream, n + 1, emits_ray,
                       ListEmittingPoint{emits_ray, merge.ray_points.data()},
                       merge.ray_scan_scratch.data());
}

// Stage 1 (merged method): the frame's rays and tally. Returns the tally (the merge's only wait).
template <class Backend>
FrameRays merge_rays(const FrameContext<Backend>& frame, const FramePoints& points,
                     const RayParameters& ray_parameters, const MergeKeys& merge_keys) {
  StageProfiler::Scope profile("tsdf merge", frame.stream);
  TsdfScratchBuffers& scratch = frame.scratch;
  const int64_t n = points.cloud.count;
  const float inverse_voxel_size = 1.0f / ray_parameters.voxel_size_m;
  const MergeTable table = clean_merge_table(frame.backend, scratch.merge, n, frame.stream);
  // The tally is reset at the end of the last frame (reset_merge_tally), so here only when that
  // frame did not get that far or the tally is new (never marked clean).
  scratch.merge.tally.resize_discard(1);
  reset_merge_tally(frame.backend, scratch.merge, frame.stream);
  scratch.merge.tally_clean = false;
  profile.mark("table");
  bundle_points(frame, points, ray_parameters, merge_keys, table);
  profile.mark("bundle");
  rank_rays(frame, n, table);
  profile.mark("rank");
  scratch.rays.rays.resize_discard(n);
  scratch.rays.weights.resize_discard(n);
  scratch.rays.colors.resize_discard(n);
  scratch.rays.pieces.resize_discard(n + 1);
  constexpr bool kTallyWithAtomics = Backend::kDevice != Device::kCpu;
  const uint32_t sequence = ++scratch.merge.sequence;
  if constexpr (kTallyWithAtomics) prepare_tally_hand_off<Backend>(scratch.merge, frame.stream);
  const WriteMergedRays<kTallyWithAtomics> kernel{
      ray_parameters,
      table,
      table.bundles,
      scratch.merge.tally.data()->stripes,
      scratch.merge.point_codes.data(),
      scratch.merge.ray_points.data(),
      points.cloud.points,
      points.colors,
      points.intensities,
      points.grey_per_intensity,
      inverse_voxel_size,
      n,
      scratch.rays.rays.data(),
      scratch.rays.weights.data(),
      scratch.rays.colors.data(),
      scratch.rays.pieces.data(),
      kTallyWithAtomics ? static_cast<MergeTallySummary*>(scratch.merge.summary->device_data())
                        : nullptr,
      kTallyWithAtomics ? scratch.merge.warps_done.data() : nullptr,
      sequence};
  parallel_for(frame.backend, frame.stream, n + 1, kernel);
  scratch.merge.table_clean = true;
  profile.mark("rays");
  FrameRays rays;
  if constexpr (kTallyWithAtomics) {
    rays.tally = collect_mapped_tally(scratch.merge, sequence, frame.stream);
  } else {
    rays.tally = collect_reduced_tally(frame.backend, scratch, n, inverse_voxel_size, frame.stream);
  }
  profile.mark("tally");
  rays.count = rays.tally.rays;
  rays.rays = scratch.rays.rays.data();
  rays.pieces = scratch.rays.pieces.data();
  rays.colors = points.has_color() ? scratch.rays.colors.data() : nullptr;
  rays.weights = scratch.rays.weights.data();
  rays.grey_per_intensity = points.grey_per_intensity;
  return rays;
}

}  // namespace covox::integrators::tsdf

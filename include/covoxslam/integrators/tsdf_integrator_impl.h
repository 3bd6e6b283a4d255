#pragma once
// Definitions of the TSDF integration steps (see tsdf_integrator.h for the algorithm), written
// once for both backends.
#include <algorithm>
#include <climits>
#include <optional>
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
  int32_t most_pieces = 0;  // the longest ray's pieces: the ray groups' levels (tsdf_traverse.h)
  int32_t low[3] = {INT32_MAX, INT32_MAX, INT32_MAX};
  int32_t high[3] = {INT32_MIN, INT32_MIN, INT32_MIN};

  Index3D low_voxel() const { return Index3D(low[0], low[1], low[2]); }
  Index3D high_voxel() const { return Index3D(high[0], high[1], high[2]); }
};
// The tally of one ray that stands for `points` input points (a merged bundle's count; 1 without
// merging).
COVOX_HD_INLINE RayTally tally_ray(const tsdf::RaySegment& ray, int64_t points,
                                   float inverse_voxel_size) {
  RayTally tally;
  // (each kind by a constant index: an index by ray.kind put the tally in local memory on the GPU)
  for (int k = 0; k < 6; ++k) tally.kinds[k] = ray.kind == k ? points : 0;
  tally.cast = ray.kind <= tsdf::kClearingRay ? 1 : 0;
  tally.voxels = tsdf::ray_voxel_count(ray, inverse_voxel_size);
  tally.most_pieces =
      static_cast<int32_t>(tsdf::ray_piece_count(static_cast<uint32_t>(tally.voxels)));
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
    sum.most_pieces = a.most_pieces > b.most_pieces ? a.most_pieces : b.most_pieces;
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

// A voxel's free-space sum (fixed point, tsdf_kernels.h) added to its band visits' sum.
template <class SumT>
COVOX_HD_INLINE void add_free_space_sum(SumT& sum, uint64_t units, float truncation) {
  const tsdf::DistanceUpdate free =
      tsdf::free_space_update(tsdf::weight_of_units(units), truncation);
  sum.weighted_distance += free.weighted_distance;
  sum.weight += free.weight;
}

// Step 5's colour blend: a frame without colour (DistanceUpdate) has none to blend. (Overloads,
// not `if constexpr`: nvcc's extended lambdas may not first-capture inside a constexpr if.)
template <class ColorView>
COVOX_HD_INLINE void blend_color(const ColorView&, int64_t, const tsdf::DistanceUpdate&, float) {}
template <class ColorView>
COVOX_HD_INLINE void blend_color(const ColorView& color_view, int64_t index,
                                 const tsdf::VoxelUpdate& update, float max_weight) {
  if (update.color_weight <= 0.0f) return;
  ColorVoxel color = color_view.load(index);
  const float color_combined = color.weight + update.color_weight;
  const float old_part = color.weight / color_combined;
  const float inverse_new = 1.0f / color_combined;
  color.r = static_cast<uint8_t>(
      fminf(255.0f, color.r * old_part + update.weighted_r * inverse_new + 0.5f));
  color.g = static_cast<uint8_t>(
      fminf(255.0f, color.g * old_part + update.weighted_g * inverse_new + 0.5f));
  color.b = static_cast<uint8_t>(
      fminf(255.0f, color.b * old_part + update.weighted_b * inverse_new + 0.5f));
  color.weight = color_combined < max_weight ? color_combined : max_weight;
  color_view.store(index, color);
}

// A voxel's one write per frame: the weighted average of the voxel and the frame's sum of its
// visits (DistanceUpdate, or VoxelUpdate with colour). Holds the pools' views: taken again after
// the pools grow.
struct VoxelMerge {
  TsdfMap::TsdfStorage::View tsdf_view;
  TsdfMap::ColorStorage::View color_view;
  float truncation;
  float max_weight;
  template <class SumT>
  COVOX_HD_INLINE void operator()(int64_t index, const SumT& update) const {
    TsdfVoxel voxel = tsdf_view.load(index);
    const float combined = voxel.weight + update.weight;
    float distance = (voxel.distance_m * voxel.weight + update.weighted_distance) / combined;
    distance =
        distance > truncation ? truncation : (distance < -truncation ? -truncation : distance);
    voxel.distance_m = distance;
    voxel.weight = combined < max_weight ? combined : max_weight;
    tsdf_view.store(index, voxel);
    blend_color(color_view, index, update, max_weight);
  }
};

// The frame's figures that step 4 and step 5 leave on the device (scratch.readback), by word.
constexpr int kFrameCountWords = 13;
constexpr int kZeroWeightFirstWord = 1;  // 1 + the first zero-weight record (sorted last); 0: none
constexpr int kOutOfRangeFirstWord =
    2;                               // 1 + the first record outside the box (before them); 0: none
constexpr int kBlockCountWord = 4;   // the frame's distinct blocks
constexpr int kActivationWords = 5;  // the activation's totals: new blocks, rejected ones
constexpr int kTableFullWord = 12;   // the in-kernel activation's blocks that found the table full
                                     // (counted among the rejected by a queued activation)
constexpr int kRunCountWord = 7;     // runs of equal keys that step 5 summed
// With free-space sums: the voxels that had only free-space visits (with every visit summed: every
// voxel the pass wrote), and those of them in blocks the hash table rejected; the summed visits
// outside the box; the band records kept.
constexpr int kFreeOnlyVoxelsWord = 8;
constexpr int kFreeRejectedWord = 9;
constexpr int kFreeOutOfRangeWord = 10;
constexpr int kBandRecordsWord = 11;
struct FrameCounts {
  uint32_t zero_weight_first = 0, out_of_range_first = 0;
  uint32_t blocks = 0, new_blocks = 0, rejected_blocks = 0;
  uint32_t runs = 0;
  uint32_t free_only_voxels = 0, free_rejected = 0, free_out_of_range = 0, band_records = 0;
  uint32_t full_blocks = 0;
};
// One copy, one wait.
inline FrameCounts read_frame_counts(const TsdfScratchBuffers& scratch, const Stream& stream) {
  uint32_t words[kFrameCountWords];
  copy_bytes(words, Device::kCpu, scratch.readback.data(), scratch.readback.device(), sizeof(words),
             stream);
  FrameCounts counts;
  counts.zero_weight_first = words[kZeroWeightFirstWord];
  counts.out_of_range_first = words[kOutOfRangeFirstWord];
  counts.blocks = words[kBlockCountWord];
  counts.new_blocks = words[kActivationWords];
  counts.rejected_blocks = words[kActivationWords + 1];
  counts.runs = words[kRunCountWord];
  counts.free_only_voxels = words[kFreeOnlyVoxelsWord];
  counts.free_rejected = words[kFreeRejectedWord];
  counts.free_out_of_range = words[kFreeOutOfRangeWord];
  counts.band_records = words[kBandRecordsWord];
  counts.full_blocks = words[kTableFullWord];
  return counts;
}
// Written by one thread of the kernel that lists the blocks (before step 5 runs).
COVOX_HD_INLINE void start_frame_counts(uint32_t* words, uint32_t blocks) {
  words[kBlockCountWord] = blocks;
  words[kZeroWeightFirstWord] = 0u;
  words[kOutOfRangeFirstWord] = 0u;
  words[kRunCountWord] = 0u;
  words[kFreeOnlyVoxelsWord] = 0u;
  words[kFreeRejectedWord] = 0u;
  words[kFreeOutOfRangeWord] = 0u;
  words[kTableFullWord] = 0u;
}
// Step 5's consumer at the run of a dropped kind: each kind is one key, so one run and one call.
COVOX_HD_INLINE void note_dropped_run(uint32_t* words, bool zero_weight, int64_t first) {
  words[zero_weight ? kZeroWeightFirstWord : kOutOfRangeFirstWord] =
      static_cast<uint32_t>(first + 1);
}
// The kept voxels and the records outside the box, from the runs and where the dropped ones start.
struct DroppedRecords {
  int64_t kept_voxels = 0;
  int64_t out_of_range = 0;
};
inline DroppedRecords dropped_records(const FrameCounts& counts, int64_t record_count) {
  DroppedRecords dropped;
  const int kinds = (counts.zero_weight_first ? 1 : 0) + (counts.out_of_range_first ? 1 : 0);
  dropped.kept_voxels = static_cast<int64_t>(counts.runs) - kinds;
  if (counts.out_of_range_first) {
    const int64_t end = counts.zero_weight_first ? counts.zero_weight_first - 1 : record_count;
    dropped.out_of_range = end - (counts.out_of_range_first - 1);
  }
  return dropped;
}

// An activation that a frame began and did not finish, because an exception stopped it, is
// finished from what the device holds as the frame unwinds (BlockHashTable::
// abandon_pending_activation; a queued one's totals are the frame's activation words): else the
// table would refuse every later frame's blocks.
class PendingActivationGuard {
 public:
  PendingActivationGuard(BlockHashTable& table, const uint32_t* queued_totals, const Stream& stream)
      : table_(table), queued_totals_(queued_totals), stream_(stream) {}
  PendingActivationGuard(const PendingActivationGuard&) = delete;
  PendingActivationGuard& operator=(const PendingActivationGuard&) = delete;
  ~PendingActivationGuard() { table_.abandon_pending_activation(queued_totals_, stream_); }

 private:
  BlockHashTable& table_;
  const uint32_t* queued_totals_;
  const Stream& stream_;
};

// A frame that sums every visit starts its pass without waiting for the count of its listed
// blocks when the last frame listed at most this many cells: then the wait is what the frame
// saves, not the pass's time lost to its loose sizing (counted_pass_threads, below). Frames with
// more (OS1-64 at 0.1 m: 6.3 M cells, KITTI: 3.5 M) wait for the count. (H100, same run,
// 2026-11-27: deferring every frame whose box bounds its cells by 2^26 made 7-Scenes 2 cm
// 0.965x, OS1-64 0.2 m (1.2 M cells) 0.95x, KITTI 1.00x and OS1-64 0.1 m 1.03x the frame time.
// Before, only frames whose box bounded their cells by 2^20 deferred, which left out the 2 cm
// frames: their boxes are ten times their listed blocks; "thirteenth pass".)
constexpr int64_t kDeferredPassMaxCells = int64_t(1) << 21;
inline bool defers_block_count(int64_t last_listed_blocks, int64_t voxels_per_block) {
  return last_listed_blocks >= 0 && last_listed_blocks * voxels_per_block <= kDeferredPassMaxCells;
}

// Threads for a pass whose work items the host knows only by a bound (`bound`: `extra` items
// and the cells of the blocks the frame lists, whose count is on the device), in a grid-stride
// loop over the count. The bound is loose (the frame's box's blocks: 4 times the listed ones in a
// 7-Scenes 5 cm frame, 10 times at 2 cm), and threads past the count cost their launch (the 5 cm
// frame's pass 8 -> 11 us on the H100 with 2^18 threads); the listed blocks change little from
// frame to frame, so the pass starts 1.5 times as many threads as the last frame's cells
// (`last_cells`, negative when unknown: then at most 2^20) and the loop covers any more.
inline int64_t counted_pass_threads(int64_t bound, int64_t extra, int64_t last_cells) {
  const int64_t wanted =
      last_cells >= 0 ? extra + last_cells + last_cells / 2 + 1024 : int64_t(1) << 20;
  return std::max<int64_t>(1, std::min(bound, wanted));
}

// The slot of a kept record's block, from the block's rank among the listed blocks: by its number
// in the frame's box (blocks listed from the traverse's marks: the scan of the marks) or by the
// record's place among the sorted records' blocks. (A kernel writing each box block's slot
// beforehand cost a launch, 2.4 us of GPU time and about 5 us of the host's per 7-Scenes 5 cm
// frame on the H100, for one load less per voxel write.)
struct RecordSlots {
  tsdf::FrameKeyCodec codec;
  const uint32_t* box_ranks;    // the scan of the box blocks' marks, or null
  const uint32_t* slots;        // per listed block
  const uint32_t* block_ranks;  // sorted records: the rank of each record's block
  const uint32_t* block_flags;  //   and whether the record starts it
  COVOX_HD_INLINE uint32_t slot_of(int64_t j, uint64_t key) const {
    return box_ranks ? slots[box_ranks[codec.block_part(key)]]
                     : slots[block_ranks[j] + block_flags[j] - 1];
  }
};

// Boxes of up to this many blocks are always marked (the CPU twin's dense grouping needs no more),
// larger ones when they have no more blocks than the frame has records, so that listing them
// costs no more than listing the sorted records' blocks.
constexpr int64_t kAlwaysMarkedBoxBlocks = int64_t(1) << 16;
inline bool marks_blocks(int64_t box_blocks, int64_t total_updates) {
  return box_blocks <= std::max<int64_t>(kAlwaysMarkedBoxBlocks, total_updates) &&
         box_blocks < (int64_t(1) << 31);
}

// The traverse's block marks for a box of `box_blocks` blocks, all clear (and one past them, for
// the scan's total). A frame clears the marks it set once it has listed them, so the array is
// cleared here only when it grows or when the last frame did not get that far.
// (A scratch array that the frame that uses it leaves all zero: cleared here only when it grows or
// when the last frame did not get that far; `clean` stays false until the frame clears it.)
template <class T>
T* clean_frame_scratch(Buffer<T>& buffer, bool& clean, size_t needed, const Stream& stream) {
  if (buffer.size() < needed || !clean) {
    const size_t size = std::max(needed, buffer.size());
    buffer.resize_discard(size);
    set_bytes(buffer.data(), buffer.device(), 0, size * sizeof(T), stream);
  }
  clean = false;
  return buffer.data();
}
inline uint32_t* clean_box_marks(TsdfScratchBuffers& scratch, int64_t box_blocks,
                                 const Stream& stream) {
  return clean_frame_scratch(scratch.box_marks, scratch.box_marks_clean,
                             static_cast<size_t>(box_blocks) + 1, stream);
}

// Free-space sums (tsdf_traverse.h, PieceTraversal::free_space_sums): a frame's free-space visits
// add their weights into one fixed-point cell per key of the frame's box, and only the band's
// visits (at most band_visits_per_ray_bound() per ray) are compacted, sorted and reduced; each
// voxel is still written once, by the band's reduction (with its free-space sum added) or by a
// pass over the listed blocks' cells. With carving, most visits are free space and one voxel is
// visited by many rays near the sensor: a 7-Scenes frame at 2 cm has 4.1 M visits, 3.8 M of them
// in free space, in 0.4 M voxels (docs/benchmarks.md, "ninth pass"). Used when the band's bound
// is at most a quarter of the visits, the frame has config.free_space_sums_min_visits of them and
// the box's cells (8 bytes each) fit in config.fixed_point_sums_max_scratch_mb: the middle way
// for boxes too large to sum every visit (16 or 48 bytes per cell, sums_every_visit below).
// The CPU twin groups the records in dense per-block arrays, which merges a voxel's visits about
// as cheaply: there the sums' atomics and pass cost more than they save (2-core CPU, OS1-64 at
// 0.2 m: 30 -> 36 ms per scan), so it uses them only when the threshold is 0 (the tests).
inline bool uses_free_space_sums(const TsdfIntegratorConfig& config, Device backend,
                                 bool marks_blocks, uint64_t box_cells, int64_t band_bound,
                                 int64_t total_updates) {
  const bool wanted = backend == Device::kCpu ? config.free_space_sums_min_visits == 0
                                              : total_updates >= config.free_space_sums_min_visits;
  const uint64_t budget = static_cast<uint64_t>(config.fixed_point_sums_max_scratch_mb) << 20;
  return config.sum_free_space_in_fixed_point && wanted && marks_blocks &&
         box_cells <= budget / sizeof(uint64_t) && 4 * band_bound <= total_updates;
}

// Every visit summed in fixed point (tsdf::VoxelSumCells: the weight, the band's distance offset
// and, with colour, the colour sums, per key of the frame's box): no record is written, sorted or
// reduced, and one pass over the listed blocks' cells writes every voxel. A free-space visit costs
// one 64-bit atomic and a band visit two to six, instead of a record through the sort and the
// reduction; a frame has the sort's five launches and the reduction's two fewer, which on the
// H100 machine, where a small frame is bound by the host's launches (docs/benchmarks.md, "eighth
// pass"), is about 60 us of the host's time (same-run A/Bs against the ninth pass's code in "tenth
// pass": 7-Scenes 5 cm 0.68-0.73, 2 cm 0.80-0.82, OS1-64 0.2 m 0.75-0.79, 0.1 m 0.79-0.80, KITTI
// 0.64-0.65 of the frame time). Used when the box's cells (16 bytes each, 48 with colour) fit in
// config.fixed_point_sums_max_scratch_mb; on the CPU twin only when
// config.free_space_sums_min_visits is 0 (the tests: its dense grouping merges a block's visits
// about as cheaply, and the large boxes' scratch misses the CPU's caches: 2-core CPU, OS1-64 0.2 m
// 0.93, 0.1 m 1.24-1.37, KITTI 1.01-1.12 with it).
inline bool sums_every_visit(const TsdfIntegratorConfig& config, Device backend, bool marks_blocks,
                             uint64_t box_cells, int cell_words) {
  const bool wanted = backend != Device::kCpu || config.free_space_sums_min_visits == 0;
  const uint64_t budget = static_cast<uint64_t>(config.fixed_point_sums_max_scratch_mb) << 20;
  return config.sum_free_space_in_fixed_point && config.sum_band_in_fixed_point && wanted &&
         marks_blocks &&
         box_cells <= budget / (sizeof(uint64_t) * static_cast<uint64_t>(cell_words));
}

// Whether a frame whose tally gave this box sums every visit (sums_every_visit).
inline bool frame_sums_every_visit(const TsdfIntegratorConfig& config, Device backend,
                                   const tsdf::FrameKeyCodec& codec, int64_t total_updates,
                                   bool colored) {
  const int64_t box_blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  return sums_every_visit(config, backend, marks_blocks(box_blocks, total_updates),
                          codec.out_of_range_key, colored ? tsdf::kSumCellWords : 2);
}
// Clears the merge's tally (tsdf_merge_rays) for the next frame. A frame does it at its end,
// where the host has queued everything and waits for the GPU anyway: right after the tally's
// read-back, the GPU waited for this launch before the frame's next ones (host trace, H100
// machine: a launch costs the host 4-5 us there; docs/benchmarks.md, "eighth pass").
// A frame whose last kernel is the pass over the listed blocks' cells has that kernel do it (one
// launch fewer): merge_tally_to_reset() hands it the stripes, or null when there is nothing to do.
inline tsdf::MergeTallyStripe* merge_tally_to_reset(TsdfScratchBuffers& scratch) {
  return scratch.merge_tally.size() != 1 || scratch.merge_tally_clean
             ? nullptr
             : scratch.merge_tally.data()->stripes;
}
template <class Backend>
void reset_merge_tally(Backend backend, TsdfScratchBuffers& scratch, const Stream& stream) {
  tsdf::MergeTallyStripe* stripes = merge_tally_to_reset(scratch);
  if (!stripes) return;
  parallel_for(backend, stream, tsdf::kMergeTallyStripes,
               [=] COVOX_HD(int64_t k) { stripes[k].reset(); });
  scratch.merge_tally_clean = true;
}

// The merge table for a frame of n points: at least twice n slots (a power of two), all free.
// A frame frees the slots it used (tsdf_merge_rays), so the table is cleared only when it grows
// or when the last frame did not get that far (an exception between its kernels).
template <class Backend>
tsdf::MergeTable clean_merge_table(Backend backend, TsdfScratchBuffers& scratch, int64_t n,
                                   const Stream& stream) {
  int log2_capacity = 10;
  while ((int64_t(1) << log2_capacity) < 2 * n) ++log2_capacity;
  const int64_t capacity = int64_t(1) << log2_capacity;
  if (log2_capacity > 31)
    throw Error("TSDF integrator: " + std::to_string(n) +
                " points in one frame are too many to merge");
  if (static_cast<int64_t>(scratch.merge_table_keys.size()) < capacity ||
      !scratch.merge_table_clean) {
    const int64_t size =
        std::max<int64_t>(capacity, static_cast<int64_t>(scratch.merge_table_keys.size()));
    scratch.merge_table_keys.resize_discard(size);
    scratch.merge_table_bundles.resize_discard(size);
    const tsdf::MergeTable all{scratch.merge_table_keys.data(), scratch.merge_table_bundles.data(),
                               0u, 0};
    parallel_for(backend, stream, size,
                 [=] COVOX_HD(int64_t slot) { all.free_slot(static_cast<uint32_t>(slot)); });
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
// With `depth_image` the points are that image's, read in place: the first kernel unprojects
// each pixel (tsdf::DepthImagePoints) and writes the point, and its colour when `colors` is
// given, to cloud.points / colors (scratch.points / scratch.colors) for the kernel after it.
template <class Backend>
tsdf_detail::RayTally tsdf_merge_rays(Backend backend, const tsdf::RayParameters& ray_parameters,
                                      const tsdf::MergeKeys& merge_keys,
                                      const PointCloudView& cloud, const Rgb8* colors,
                                      const float* intensities, float grey_per_intensity,
                                      TsdfScratchBuffers& scratch, const Stream& stream,
                                      const tsdf::DepthImagePoints* depth_image = nullptr) {
  StageProfiler::Scope profile("tsdf merge", stream);
  const int64_t n = cloud.count;
  const float inverse_voxel_size = 1.0f / ray_parameters.voxel_size_m;
  const tsdf::MergeTable table = tsdf_detail::clean_merge_table(backend, scratch, n, stream);
  // The tally is reset at the end of the last frame (tsdf_detail::reset_merge_tally), so here
  // only when that frame did not get that far or the tally is new (never marked clean).
  scratch.merge_tally.resize_discard(1);
  tsdf::MergeTallyStripe* stripes = scratch.merge_tally.data()->stripes;
  tsdf_detail::reset_merge_tally(backend, scratch, stream);
  scratch.merge_tally_clean = false;
  profile.mark("table");
  scratch.point_codes.resize_discard(n);
  uint32_t* codes = scratch.point_codes.data();
  const Vec3f* points = cloud.points;
  const bool has_color = colors || intensities;
  const bool reads_image = depth_image != nullptr;
  const tsdf::DepthImagePoints image = reads_image ? *depth_image : tsdf::DepthImagePoints{};
  // (reading the image: the points and colours written for the ray kernel, which `cloud` names)
  Vec3f* image_points = reads_image ? scratch.points.data() : nullptr;
  Rgb8* image_colors = reads_image && colors ? scratch.colors.data() : nullptr;
  if (reads_image && (cloud.points != image_points || (colors && colors != image_colors))) {
    throw Error(
        "TSDF integrator: a depth image read in place must name the scratch points and colours "
        "(internal error)");
  }
  // Points of one voxel lie within 2^31 merge units of each other (per axis) when the voxel's
  // diagonal is under about 1.8 m (voxels under 1 m): their coordinates sum in two warp reductions
  // each instead of four (warp_sum_clustered).
  const bool clustered =
      ray_parameters.voxel_size_m * 1.7320508f * tsdf::kMergeUnitsPerMetre < 2.0e9f;
  // Every point: its ray, its bundle (claimed or found in the table), its sums added. A warp's
  // points of one bundle add their sums together, one atomic per field (warp_reduce.h): a 5 cm
  // voxel holds about 80 pixels of a depth image, whose atomics would otherwise queue up. Each
  // group of a warp's lanes reduces in turn, so the reductions are few: the count and the first
  // point come from the group's mask (the lanes of a warp hold consecutive points), two colour
  // channels share a word (a sum of 32 is at most 8160).
  parallel_for(backend, stream, n, [=] COVOX_HD(int64_t i) {
    const uint32_t lanes = warp_lanes();
    Vec3f point;
    Rgb8 color;
    if (reads_image) {  // the same for every point
      const int64_t pixel = image.pixel_at(i);
      point = image.point(pixel);
      image_points[i] = point;
      color = image_colors ? image.colors[pixel] : Rgb8{};
      if (image_colors) image_colors[i] = color;
    } else {
      point = points[i];
      color = tsdf::color_of(colors, intensities, grey_per_intensity, i);
    }
    uint64_t key = 0;
    uint32_t code =
        merge_keys.classify(tsdf::make_ray(ray_parameters, point), inverse_voxel_size, &key);
    if (code != 0u) key = tsdf::kFreeMergeKey;  // no bundle
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
        const uint32_t red_green = warp_sum(
            peers, static_cast<uint32_t>(color.r) | (static_cast<uint32_t>(color.g) << 16));
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
        atomic_add(&stripes[tsdf::merge_tally_stripe(i)].kinds[tsdf::kDroppedNonFinite + k],
                   static_cast<uint64_t>(dropped));
      }
    }
  });
  profile.mark("bundle");
  // The points that emit a ray, listed in point order (the same on both backends): ray m's point
  // is ray_points[m], and ray_points[n] holds the count of rays. The scan of the points' flags
  // lists each emitting point at its rank as the rank is known (its output reads the flag again,
  // from cache), so that the ray kernel below runs one thread per ray, not per point: a warp then
  // tallies 32 rays in one set of atomics where one per point had ~1.3 at 5 cm (H100, 7-Scenes:
  // docs/benchmarks.md, "thirteenth pass").
  scratch.ray_points.resize_discard(n + 1);
  uint32_t* ray_points = scratch.ray_points.data();
  const tsdf::PointBundle* bundles = table.bundles;
  const auto emits_ray = [=] COVOX_HD(int64_t i) -> uint32_t {
    if (i == n) return 0u;
    const uint32_t code = codes[i];
    return code == tsdf::kAlonePoint ||
                   (tsdf::is_bundle_slot(code) && bundles[code].first == static_cast<uint32_t>(i))
               ? 1u
               : 0u;
  };
  const auto list_emitting_point = [=] COVOX_HD(int64_t i, uint32_t rank) {
    if (i == n) {
      ray_points[n] = rank;
    } else if (emits_ray(i) != 0u) {
      ray_points[rank] = static_cast<uint32_t>(i);
    }
  };
  scratch.ray_scan_scratch.resize_discard(
      Backend::kDevice == Device::kCpu ? n + 1 : 0);  // the CPU twin's only
  exclusive_scan_of<2>(backend, stream, n + 1, emits_ray, list_emitting_point,
                       scratch.ray_scan_scratch.data());
  profile.mark("rank");
  scratch.rays.resize_discard(n);
  scratch.ray_weights.resize_discard(n);
  scratch.ray_colors.resize_discard(n);
  scratch.counts.resize_discard(n + 1);
  uint32_t* ray_pieces = scratch.counts.data();
  tsdf::RaySegment* merged_rays = scratch.rays.data();
  float* weights = scratch.ray_weights.data();
  Rgb8* ray_colors = scratch.ray_colors.data();
  // Each ray (thread m < the count) written from its point, its bundle's slot freed (the table is
  // clean again) and, on the GPU, the ray added to the tally, per warp; thread m == count writes
  // the piece counts' end, and the threads past it leave. On the CPU twin a "warp" is one call,
  // so the tally's atomics would be one per ray and counter, on lines both cores write: the rays
  // are tallied by a reduction afterwards instead (2-core CPU, OS1-64 scan: this step 3.0 ->
  // 0.6-0.9 ms, the reduction 0.2-0.3 ms; the whole merge 4.5 -> 2.5 ms).
  constexpr bool kTallyWithAtomics = Backend::kDevice != Device::kCpu;
  // The hand-off of the tally (GPU; tsdf::MergeTallySummary): the warps done, the summary, the
  // frame's stamp.
  tsdf::MergeTallySummary* summary = nullptr;
  uint32_t* warps_done = nullptr;
  const uint32_t sequence = ++scratch.merge_sequence;
  if constexpr (kTallyWithAtomics) {
    if (!scratch.merge_summary) {
      scratch.merge_summary =
          std::make_unique<MappedHostBytes>(Backend::kDevice, sizeof(tsdf::MergeTallySummary));
    }
    summary = static_cast<tsdf::MergeTallySummary*>(scratch.merge_summary->device_data());
    if (scratch.merge_warps_done.size() != 1) {
      scratch.merge_warps_done.resize_discard(1);
      scratch.merge_warps_done.fill_bytes(0, stream);
    }
    warps_done = scratch.merge_warps_done.data();
  }
  parallel_for(backend, stream, n + 1, [=] COVOX_HD(int64_t m) {
    const uint32_t ray_total = ray_points[n];
    if (m > ray_total) return;
    const uint32_t lanes = warp_lanes();
    const bool emits = m < ray_total;
    tsdf_detail::RayTally own;              // this thread's ray, if it has one
    if (m == ray_total) ray_pieces[m] = 0;  // the end of the counts
    if (emits) {
      const int64_t i = static_cast<int64_t>(ray_points[m]);
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
      ray_pieces[m] = static_cast<uint32_t>(own.most_pieces);
      if (ray.kind > tsdf::kClearingRay) {  // rare: a bundle's mean point dropped (closer than
                                            // min_ray_length_m)
        atomic_add(&stripes[tsdf::merge_tally_stripe(m)].kinds[ray.kind],
                   static_cast<uint64_t>(count));
      }
    }
    // The warp's rays summed, then one atomic per counter (a warp's counts fit in 32 bits).
    if (!kTallyWithAtomics) return;
    const bool leader = warp_lane() == warp_first_lane(lanes);
    if (warp_ballot(lanes, emits) != 0u) {
      const auto sum32 = [lanes](int64_t value) {
        return warp_sum(lanes, static_cast<uint32_t>(value));
      };
      const uint32_t surface_points = sum32(own.kinds[tsdf::kSurfaceRay]);
      const uint32_t clearing_rays = sum32(own.kinds[tsdf::kClearingRay]);
      const uint32_t rays = sum32(own.rays);
      const uint32_t cast = sum32(own.cast);
      const uint32_t visits = sum32(own.voxels);
      const int32_t most_pieces = warp_max(lanes, own.most_pieces);
      const int32_t box[6] = {warp_min(lanes, own.low[0]),  warp_min(lanes, own.low[1]),
                              warp_min(lanes, own.low[2]),  warp_max(lanes, own.high[0]),
                              warp_max(lanes, own.high[1]), warp_max(lanes, own.high[2])};
      if (leader) {
        tsdf::MergeTallyStripe& stripe = stripes[tsdf::merge_tally_stripe(m)];
        atomic_add(&stripe.kinds[tsdf::kSurfaceRay], static_cast<uint64_t>(surface_points));
        if (clearing_rays != 0u)
          atomic_add(&stripe.kinds[tsdf::kClearingRay], static_cast<uint64_t>(clearing_rays));
        atomic_add(&stripe.cast, static_cast<uint64_t>(cast));
        atomic_add(&stripe.rays, static_cast<uint64_t>(rays));
        atomic_add(&stripe.voxels, static_cast<uint64_t>(visits));
        atomic_max(&stripe.most_pieces, most_pieces);
        for (int axis = 0; axis < 3; ++axis) {
          atomic_min(&stripe.low[axis], box[axis]);
          atomic_max(&stripe.high[axis], box[3 + axis]);
        }
      }
    }
    // The hand-off: the warps of threads 0..ray_total count themselves done; the last one out
    // sums the stripes into the summary and stamps it.
    uint32_t done = 0;
    if (leader) {
      device_fence();  // this warp's atomics before its count
      done = atomic_add(warps_done, 1u);
    }
    done = warp_broadcast(lanes, done, warp_first_lane(lanes));
    if (done != ray_total / 32u) return;  // (ray_total + 1 threads: ray_total / 32 + 1 warps)
    device_fence();                       // the other warps' atomics before the stripes' reads
    const tsdf::MergeTallyStripe sum = tsdf::sum_merge_tally_stripes(stripes, lanes);
    if (!leader) return;
    summary->sum = sum;
    summary->sequence = sequence;
    *warps_done = 0;  // for the next frame
  });
  scratch.merge_table_clean = true;
  profile.mark("rays");
  // The tally: on the GPU the summary the kernel left in host memory, once the stream is done
  // (no copy); on the CPU the stripes themselves.
  tsdf::MergeTally host;
  int stripe_count = tsdf::kMergeTallyStripes;
  if constexpr (kTallyWithAtomics) {
    stream.synchronize();
    const auto* written =
        static_cast<const tsdf::MergeTallySummary*>(scratch.merge_summary->host_data());
    if (written->sequence != sequence) {
      scratch.merge_warps_done.fill_bytes(0, stream);
      throw Error("TSDF integrator: the merge's tally of frame " + std::to_string(sequence) +
                  " did not arrive (the summary is frame " + std::to_string(written->sequence) +
                  "'s); the frame was not integrated");
    }
    host.stripes[0] = written->sum;
    stripe_count = 1;
  } else {
    copy_bytes(&host, Device::kCpu, stripes, scratch.merge_tally.device(), sizeof(host), stream);
  }
  tsdf_detail::RayTally tally;
  for (int k = 0; k < stripe_count; ++k) {
    const tsdf::MergeTallyStripe& stripe = host.stripes[k];
    tsdf_detail::RayTally part;
    for (int k = 0; k < 6; ++k) part.kinds[k] = static_cast<int64_t>(stripe.kinds[k]);
    part.cast = static_cast<int64_t>(stripe.cast);
    part.rays = static_cast<int64_t>(stripe.rays);
    part.voxels = static_cast<int64_t>(stripe.voxels);
    part.most_pieces = stripe.most_pieces;
    for (int axis = 0; axis < 3; ++axis) {
      part.low[axis] = stripe.low[axis];
      part.high[axis] = stripe.high[axis];
    }
    tally = tsdf_detail::AddTallies{}(tally, part);
  }
  if constexpr (!kTallyWithAtomics) {
    // The rays' part of the tally (the counters hold the dropped points' only).
    const int64_t ray_count = ray_points[n];  // host memory on the CPU twin
    const tsdf_detail::RayTally rays_tally = transform_reduce(
        backend, stream, thrust::make_counting_iterator<int64_t>(0), ray_count,
        [=](int64_t m) {
          const tsdf::RaySegment& ray = merged_rays[m];
          tsdf_detail::RayTally own =
              tsdf_detail::tally_ray(ray, static_cast<int64_t>(weights[m]), inverse_voxel_size);
          if (ray.kind > tsdf::kClearingRay)
            own.kinds[ray.kind] = 0;  // counted by the kernel's atomic
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
void tsdf_fuse_updates(Backend backend, const TsdfIntegratorConfig& config,
                       const tsdf::FrameUpdates& frame, int64_t ray_count, TsdfMap& map,
                       TsdfScratchBuffers& scratch, IntegrationStats& stats,
                       StageProfiler::Scope& profile, const Stream& stream) {
  constexpr bool kColored = std::is_same<ValueT, tsdf::ColorVisit>::value;
  using SumT = std::conditional_t<kColored, tsdf::VoxelUpdate, tsdf::DistanceUpdate>;
  const tsdf::FrameKeyCodec codec = frame.codec;
  const int64_t total_updates = frame.total_updates;
  const float truncation = config.truncation_distance_m;
  const KeyT zero_weight_key = static_cast<KeyT>(codec.zero_weight_key);
  const KeyT out_of_range_key = static_cast<KeyT>(codec.out_of_range_key);
  // The traverse marks the frame's blocks in a flag array over the frame's box when the box is
  // not too large (almost always): the blocks are then listed and allocated before the sort.
  const int64_t box_blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  const bool mark_blocks = tsdf_detail::marks_blocks(box_blocks, total_updates);
  uint32_t* box_marks =
      mark_blocks ? tsdf_detail::clean_box_marks(scratch, box_blocks, stream) : nullptr;
  // Every visit summed per voxel in fixed point when the box's cells fit (tsdf_detail::
  // sums_every_visit), else the free-space visits only when that pays (tsdf_detail::
  // uses_free_space_sums): the band's visits are then at most band_bound records.
  const uint64_t box_cells = codec.out_of_range_key;  // one per key of the box
  const int cell_words = kColored ? tsdf::kSumCellWords : 2;
  // (decided once, in tsdf_integrate_points: such a frame comes with its ray groups)
  const bool sum_every_visit = frame.walks_ray_groups;
  const int64_t band_bound = std::min<int64_t>(
      total_updates, ray_count * tsdf::band_visits_per_ray_bound(truncation, frame.voxel_size));
  uint64_t* free_space_sums = nullptr;
  uint64_t* free_out_of_range = nullptr;  // the word past the box's cells: visits summed outside it
  tsdf::VoxelSumCells sum_cells;
  if (sum_every_visit) {
    sum_cells.words =
        tsdf_detail::clean_frame_scratch(scratch.fixed_point_sums, scratch.fixed_point_sums_clean,
                                         box_cells * cell_words + 1, stream);
    sum_cells.stride = cell_words;
    sum_cells.truncation = truncation;
    sum_cells.aggregate_in_warp = config.aggregate_free_space_in_warp;
    free_out_of_range = sum_cells.words + box_cells * cell_words;
  } else if (tsdf_detail::uses_free_space_sums(config, Backend::kDevice, mark_blocks, box_cells,
                                               band_bound, total_updates)) {
    free_space_sums = tsdf_detail::clean_frame_scratch(
        scratch.fixed_point_sums, scratch.fixed_point_sums_clean, box_cells + 1, stream);
    free_out_of_range = free_space_sums + box_cells;
  }
  const tsdf::PieceTraversal<KeyT, ValueT> traversal{frame,
                                                     zero_weight_key,
                                                     scratch.piece_offsets.data(),
                                                     truncation,
                                                     box_marks,
                                                     free_space_sums,
                                                     free_out_of_range,
                                                     true,
                                                     sum_cells};
  // The records (none when every visit is summed). Keys are 32-bit when the frame's box allows
  // (almost always): half the key bytes through the traverse's writes, every radix pass and the
  // reduction.
  const int64_t record_space = sum_every_visit ? 0 : total_updates;
  auto key_buffers = scratch.update_key_buffers<KeyT>();
  for (int k = 0; k < 2; ++k) key_buffers[k]->resize_discard(record_space);
  KeyT* keys = key_buffers[0]->data();
  KeyT* keys_alt = key_buffers[1]->data();
  auto value_buffers = scratch.record_value_buffers<ValueT>();
  for (Buffer<ValueT>* buffer : value_buffers) buffer->resize_discard(record_space);
  ValueT* values = value_buffers[0]->data();
  ValueT* values_alt = value_buffers[1]->data();
  // The frame's figures left on the device (tsdf_detail::FrameCounts) and read back together.
  scratch.readback.resize_discard(tsdf_detail::kFrameCountWords);
  uint32_t* counts_on_device = scratch.readback.data();
  // With free-space sums only the band's records are kept, compacted in visit order into the first
  // band_bound places of the other record arrays (tsdf::BandRecords; the GPU's traverse does it as
  // it copies its records out), so that the sort and the reduction see band_bound records: a
  // bound the host knows without a read-back.
  tsdf::BandRecords<KeyT, ValueT> band;
  if (free_space_sums) {
    band =
        tsdf::BandRecords<KeyT, ValueT>{keys_alt, values_alt, band_bound,
                                        counts_on_device + tsdf_detail::kBandRecordsWord, nullptr};
    if constexpr (std::is_same<Backend, CpuBackend>::value) {
      scratch.record_ranks.resize_discard(total_updates + 1);
      band.ranks = scratch.record_ranks.data();
    }
  }
  int64_t record_count = total_updates;  // the records step 5 reads (the dropped ones sort last)
  if (sum_every_visit) {
    tsdf::sum_ray_groups(backend, stream, traversal,
                         tsdf::RayGroups{frame.ray_pieces, frame.most_ray_pieces, frame.ray_count,
                                         tsdf::ray_group_count(frame.ray_count)});
    record_count = 0;
  } else {
    tsdf::traverse_pieces(backend, stream, frame.piece_bound, total_updates, traversal,
                          tsdf::RecordArrays<KeyT, ValueT>{keys, values}, band);
  }
  if (band.keys) {
    std::swap(keys, keys_alt);
    std::swap(values, values_alt);
    record_count = band_bound;
  }
  profile.mark("2b traverse");

  // 3. (CPU twin) group by voxel in dense per-block arrays (tsdf_group_updates_cpu.h): the same
  //    voxels and (within rounding) sums as the sort and run sums below, with a third of the
  //    moves. Its merged records are runs of one, and none is dropped.
  stats.records_grouped = record_count;
  const KeyT* record_keys = keys;
  SumT* merged_updates = nullptr;  // the CPU twin's merged records' sums
  tsdf::GroupCounts grouping;
  bool grouped = false;
  if constexpr (std::is_same<Backend, CpuBackend>::value) {
    if (!sum_every_visit && tsdf::dense_grouping_fits(codec)) {
      key_buffers[2]->resize_discard(record_count);
      KeyT* merged_keys = key_buffers[2]->data();
      if constexpr (kColored) {
        scratch.merged_updates.resize_discard(record_count);
        merged_updates = scratch.merged_updates.data();
        const tsdf::VoxelUpdateOfRecord<KeyT> update_of{frame, keys_alt, values_alt,
                                                        out_of_range_key, truncation};
        grouping = tsdf::group_updates_by_voxel_cpu(codec, keys, values, record_count, keys_alt,
                                                    values_alt, merged_keys, merged_updates,
                                                    update_of, tsdf::MergeUpdates());
      } else {
        merged_updates = values;  // free once the records have moved
        const ValueT* moved = values_alt;
        grouping = tsdf::group_updates_by_voxel_cpu(
            codec, keys, values, record_count, keys_alt, values_alt, merged_keys, merged_updates,
            [moved](int64_t j) { return moved[j]; }, tsdf::MergeUpdates());
      }
      record_keys = merged_keys;
      record_count = grouping.voxels;
      grouped = true;
      profile.mark("3 group by voxel");
    }
  }

  // 4. the frame's distinct blocks, listed and allocated in one batch (the hash table sees a few
  //    hundred blocks, not one key per record). Listed from the traverse's marks (before the
  //    sort), or else from the sorted records, block-major, where each block's records form one
  //    run. On the GPU the activation is queued for the blocks counted on the device (at most
  //    one per box block and per record) and its totals come back while the records are sorted,
  //    so the host's wait overlaps the sort; when the table might have to grow it needs the exact
  //    count first (activate_queued says no), and on the CPU a read-back is free.
  // (with sums the records are the band's only, or none: the kept visits bound the blocks)
  const int64_t listed_bound = free_out_of_range ? total_updates : record_count;
  const int64_t block_bound = std::max<int64_t>(1, std::min<int64_t>(box_blocks, listed_bound));
  scratch.block_indices.resize_discard(block_bound);
  scratch.slots.resize_discard(block_bound);
  scratch.is_new.resize_discard(block_bound);
  Index3D* block_indices = scratch.block_indices.data();
  uint32_t* slots = scratch.slots.data();
  const uint32_t* block_ranks = nullptr;
  const uint32_t* block_flags = nullptr;
  bool queued = false;
  ActivateResult activation;
  tsdf_detail::FrameCounts counts;
  const auto activate_listed_blocks = [&] {
    if (Backend::kDevice != Device::kCpu) {
      queued = map.blocks().activate_queued(
          block_indices, counts_on_device + tsdf_detail::kBlockCountWord, block_bound, slots,
          scratch.is_new.data(), counts_on_device + tsdf_detail::kActivationWords, stream);
    }
    if (!queued) {
      counts = tsdf_detail::read_frame_counts(scratch, stream);
      activation =
          map.blocks().activate(block_indices, counts.blocks, slots, scratch.is_new.data(), stream);
    }
  };
  std::optional<PendingReadBack> activation_totals;
  BlockActivator activator;
  bool activates_while_listing = false;
  const tsdf_detail::PendingActivationGuard activation_guard(
      map.blocks(), counts_on_device + tsdf_detail::kActivationWords, stream);
  const uint32_t* box_ranks = nullptr;
  if (mark_blocks) {
    scratch.block_ranks.resize_discard(box_blocks + 1);
    uint32_t* marked_ranks = scratch.block_ranks.data();
    box_ranks = marked_ranks;
    // The marks scanned into ranks, and as each rank is known the marked block listed at it and
    // its mark cleared for the next frame (the scan has read it); the rank past the box is the
    // count. One launch: the listing was a kernel of its own (2.6 us of GPU time and 5-10 us of
    // the host's per 7-Scenes 5 cm frame on the H100 machine, docs/benchmarks.md "tenth pass").
    // A frame that sums every visit also activates each listed block there (BlockActivator,
    // block_activator.h: no activation kernel; its totals come back at the frame's end).
    activates_while_listing =
        sum_every_visit && map.blocks().begin_in_kernel_activation(block_bound, &activator, stream);
    const BlockActivator listing_activator = activator;
    const bool activate_here = activates_while_listing;
    uint8_t* listed_is_new = scratch.is_new.data();
    const auto is_marked = [=] COVOX_HD(int64_t b) -> uint32_t {
      return box_marks[b] != 0u ? 1u : 0u;
    };
    const auto list_marked = [=] COVOX_HD(int64_t b, uint32_t rank) {
      marked_ranks[b] = rank;
      if (b == box_blocks) {
        tsdf_detail::start_frame_counts(counts_on_device, rank);
      } else if (box_marks[b] != 0u) {
        const Index3D block = codec.block(static_cast<uint64_t>(b) << codec.voxel_bits);
        block_indices[rank] = block;
        if (activate_here) {
          bool fresh = false;
          slots[rank] = listing_activator.activate(block, &fresh);
          listed_is_new[rank] = fresh ? 1u : 0u;
        }
        box_marks[b] = 0u;
      }
    };
    // An insertion is a chain of dependent probes: one block per GPU thread then (with eight per
    // thread, as the scan reads arrays, the 2 cm frame's scan took 29 us instead of 7; H100).
    if (activate_here) {
      exclusive_scan_of<1>(backend, stream, box_blocks + 1, is_marked, list_marked);
    } else {
      exclusive_scan_of(backend, stream, box_blocks + 1, is_marked, list_marked);
    }
    if (!activates_while_listing) activate_listed_blocks();
    scratch.box_marks_clean = true;
    if (queued) {
      activation_totals.emplace(counts_on_device + tsdf_detail::kBlockCountWord, Backend::kDevice,
                                3 * sizeof(uint32_t), stream);
    }
    profile.mark("4a list and activate marked blocks");
  }
  if (!grouped && !sum_every_visit) {
    // 3. group by voxel: a stable sort keeps each voxel's records in ray order, so the float
    //    sums are the same every run. Records to drop (outside the key range, zero weight) sort
    //    last, one run per kind.
    radix_sort_pairs_swapping(backend, stream, keys, values, record_count, codec.key_bits, keys_alt,
                              values_alt);
    record_keys = keys;  // the sort may have swapped the buffers
    profile.mark("3 sort records");
  }
  if (!mark_blocks) {
    scratch.block_flags.resize_discard(record_count + 1);
    scratch.block_ranks.resize_discard(record_count + 1);
    uint32_t* flags = scratch.block_flags.data();
    uint32_t* ranks = scratch.block_ranks.data();
    block_flags = flags;
    block_ranks = ranks;
    parallel_for(backend, stream, record_count + 1, [=] COVOX_HD(int64_t v) {
      const bool kept = v < record_count && record_keys[v] < out_of_range_key;
      flags[v] = kept && (v == 0 ||
                          codec.block_part(record_keys[v]) != codec.block_part(record_keys[v - 1]))
                     ? 1u
                     : 0u;
    });
    exclusive_scan(backend, stream, static_cast<const uint32_t*>(flags), record_count + 1, ranks);
    parallel_for(backend, stream, record_count + 1, [=] COVOX_HD(int64_t v) {
      if (flags[v]) block_indices[ranks[v]] = codec.block(record_keys[v]);
      if (v == 0) tsdf_detail::start_frame_counts(counts_on_device, ranks[record_count]);
    });
    activate_listed_blocks();
    profile.mark("4a list and activate sorted blocks");
  }
  // A frame that sums every visit activated its blocks while listing them and does not wait for
  // the activation's totals: they come back with the frame's other figures at its end (the pass
  // hands them over), where any block whose new slot lies past the voxel pool is written by a
  // second pass once the pool has grown (rare: the pool grows geometrically); the first pass
  // writes the blocks whose slots the pool already holds, and clears the new ones. A small frame
  // does not wait at all: its pass reads the listed blocks' count on the device; a larger one
  // (by the last frame's count) waits for that count only (kDeferredPassMaxCells). With the
  // levels scan and the activation kernels gone too, a 7-Scenes 5 cm frame went from eleven
  // kernels and three waits to seven and two (H100: 0.124 -> 0.103 ms in two same-run steps;
  // docs/benchmarks.md, "twelfth pass"); six kernels since the thirteenth.
  const bool activation_deferred = activates_while_listing;
  const bool pass_counted_on_device =
      activation_deferred &&
      tsdf_detail::defers_block_count(scratch.last_listed_blocks, map.voxels_per_block());
  if (activation_deferred) {
    if (!pass_counted_on_device) counts = tsdf_detail::read_frame_counts(scratch, stream);
  } else if (activation_totals) {
    uint32_t totals[3];
    activation_totals->wait(totals);
    counts.blocks = totals[0];
    activation = map.blocks().finish_queued_activation(totals[1], totals[2], stream);
  } else if (queued) {  // listed after the sort: its totals come back now
    counts = tsdf_detail::read_frame_counts(scratch, stream);
    activation =
        map.blocks().finish_queued_activation(counts.new_blocks, counts.rejected_blocks, stream);
  }
  stats.blocks_allocated = activation.num_new;
  profile.mark("4b hash activate");
  map.ensure_pool_capacity(stream);
  // The slots below this one have voxels in the pool (with the activation deferred, new ones past
  // it wait for the second pass).
  const uint32_t pool_slots =
      static_cast<uint32_t>(std::min<int64_t>(map.pool_slots(), kInvalidSlot));
  profile.mark("4c pool capacity");

  // Clear new blocks: a new block may reuse the slot of an erased one. (The voxel writes below
  // mark the blocks changed, for the ESDF and the mesh.)
  auto tsdf_view = map.tsdf().view();
  auto color_view = map.color().view();
  uint8_t* block_changed = map.block_changed().data();
  auto esdf_view = map.esdf().view();
  const uint8_t* is_new = scratch.is_new.data();
  const int64_t voxels_per_block = map.voxels_per_block();
  if (activation.num_new > 0 &&
      !sum_every_visit) {  // (with every visit summed, the pass clears them)
    parallel_for(backend, stream, int64_t(counts.blocks) * voxels_per_block,
                 [=] COVOX_HD(int64_t i) {
                   const int64_t b = i / voxels_per_block;
                   if (!is_new[b] || slots[b] == kInvalidSlot) return;
                   const int64_t index =
                       static_cast<int64_t>(slots[b]) * voxels_per_block + i % voxels_per_block;
                   tsdf_view.store(index, TsdfVoxel{});
                   color_view.store(index, ColorVoxel{});
                   esdf_view.store(index, EsdfVoxel{});
                 });
  }
  profile.mark("4d clear new blocks");

  // 5. each voxel's records summed and written once: a weighted average with the voxel, given
  //    the index of the voxel's first record and the sum of its updates. The runs of dropped
  //    records (sorted last) only leave their first index, from which their counts follow.
  const tsdf_detail::RecordSlots record_slots{codec, box_ranks, slots, block_ranks, block_flags};
  const float max_weight = config.max_weight;
  const tsdf_detail::VoxelMerge merge_into_voxel{tsdf_view, color_view, truncation, max_weight};
  const auto write_voxel = [=] COVOX_HD(int64_t j, const SumT& band_update) {
    const KeyT key = record_keys[j];
    if (key >= out_of_range_key) {
      tsdf_detail::note_dropped_run(counts_on_device, key == zero_weight_key, j);
      return;
    }
    SumT update = band_update;
    if (free_space_sums) {  // the voxel's free-space visits (taken, so the pass below skips it)
      const uint64_t units = free_space_sums[key];
      if (units != 0) {
        free_space_sums[key] = 0;
        tsdf_detail::add_free_space_sum(update, units, truncation);
      }
    }
    const uint32_t slot = record_slots.slot_of(j, key);
    if (slot == kInvalidSlot) return;
    if (j == 0 || codec.block_part(record_keys[j - 1]) != codec.block_part(key)) {
      block_changed[slot] = kAllPending;  // once per block: its first voxel
    }
    if (update.weight <= 0.0f) return;
    merge_into_voxel(static_cast<int64_t>(slot) * voxels_per_block + codec.voxel_in_block(key),
                     update);
  };
  uint32_t* runs_counted = counts_on_device + tsdf_detail::kRunCountWord;
  // With free-space sums the sorted records are the band's, then zero-weight fill up to the bound:
  // only the band's are read (a fill of 100 k records, one run, cost a serial walk over its tiles).
  const uint32_t* live_records =
      band.keys ? counts_on_device + tsdf_detail::kBandRecordsWord : nullptr;
  if (sum_every_visit) {
    // no records: the pass below writes every voxel
  } else if (grouped) {  // one record per voxel, none dropped
    consume_run_sums<SumT>(backend, stream, record_keys, record_count,
                           tsdf_detail::ArrayTerm<SumT>{merged_updates}, tsdf::MergeUpdates(),
                           write_voxel, scratch.run_tile_parts, runs_counted);
  } else if constexpr (kColored) {
    const tsdf::VoxelUpdateOfRecord<KeyT> update_of{frame, keys, values, out_of_range_key,
                                                    truncation};
    consume_run_sums<SumT>(backend, stream, record_keys, record_count, update_of,
                           tsdf::MergeUpdates(), write_voxel, scratch.run_tile_parts, runs_counted,
                           live_records);
  } else {
    consume_run_sums<SumT>(backend, stream, record_keys, record_count,
                           tsdf_detail::ArrayTerm<SumT>{values}, tsdf::MergeUpdates(), write_voxel,
                           scratch.run_tile_parts, runs_counted, live_records);
  }
  // The voxels with free-space visits only (with every visit summed: every voxel): every cell of
  // the listed blocks read (and cleared), a new block's voxels cleared first when every visit is
  // summed; the first pass also hands over the count of summed visits outside the box and clears
  // the merge's tally stripes, if any (tsdf_detail::reset_merge_tally). A pass writes the blocks
  // whose slots lie in [slot_begin, slot_end) (and, the first, counts the rejected blocks'
  // visited cells), leaving the others' cells for the second. `device_blocks`: the listed blocks'
  // count on the device, `blocks` then only its bound (a grid-stride loop covers the count).
  const int32_t voxels_per_side = codec.voxels_per_side;
  const int voxel_bits = codec.voxel_bits;
  const auto write_listed_cells = [&](bool first_pass, int64_t blocks,
                                      const uint32_t* device_blocks, uint32_t slot_begin,
                                      uint32_t slot_end) {
    // (the pools' views taken now: the second pass runs after they grew)
    const auto tsdf_view = map.tsdf().view();
    const auto color_view = map.color().view();
    const auto esdf_view = map.esdf().view();
    uint8_t* block_changed = map.block_changed().data();
    const tsdf_detail::VoxelMerge merge_into_voxel{tsdf_view, color_view, truncation, max_weight};
    tsdf::MergeTallyStripe* tally_stripes =
        first_pass ? tsdf_detail::merge_tally_to_reset(scratch) : nullptr;
    const bool hands_over_activation = first_pass && activates_while_listing;
    const int64_t extra = first_pass ? 1 + (tally_stripes ? tsdf::kMergeTallyStripes : 0) : 0;
    const int64_t bound = extra + blocks * voxels_per_block;
    const int64_t threads = device_blocks
                                ? tsdf_detail::counted_pass_threads(
                                      bound, extra, scratch.last_listed_blocks * voxels_per_block)
                                : bound;
    parallel_for(backend, stream, threads, [=] COVOX_HD(int64_t t) {
      // the cells first (a warp's 32 cells aligned), then the extra items
      const int64_t cells =
          device_blocks ? static_cast<int64_t>(*device_blocks) * voxels_per_block : bound - extra;
      uint32_t written = 0, rejected = 0;
      for (int64_t i = t; i < cells + extra; i += threads) {
        if (i >= cells) {  // the hand-over, then the tally's stripes
          if (i == cells) {
            counts_on_device[tsdf_detail::kFreeOutOfRangeWord] =
                static_cast<uint32_t>(*free_out_of_range);
            *free_out_of_range = 0;
            if (hands_over_activation) {
              uint32_t totals[3];
              activator.hand_over_totals(totals);
              counts_on_device[tsdf_detail::kActivationWords] = totals[0];
              counts_on_device[tsdf_detail::kActivationWords + 1] = totals[1];
              counts_on_device[tsdf_detail::kTableFullWord] = totals[2];
            }
          } else {
            tally_stripes[i - cells - 1].reset();
          }
          continue;
        }
        const int64_t b = i >> voxel_bits;  // voxels_per_block = 2^voxel_bits (no 64-bit division)
        const uint32_t slot = slots[b];
        if (slot == kInvalidSlot ? !first_pass : (slot < slot_begin || slot >= slot_end)) continue;
        const Index3D block = block_indices[b];
        const uint64_t block_key = codec.key(Index3D(
            block.x * voxels_per_side, block.y * voxels_per_side, block.z * voxels_per_side));
        const uint64_t key = block_key | static_cast<uint64_t>(i & (voxels_per_block - 1));
        const int64_t index = static_cast<int64_t>(slot) * voxels_per_block +
                              (key & ((uint64_t(1) << voxel_bits) - 1));
        if (sum_every_visit && slot != kInvalidSlot &&
            is_new[b]) {  // a new block may reuse an erased one's slot
          tsdf_view.store(index, TsdfVoxel{});
          color_view.store(index, ColorVoxel{});
          esdf_view.store(index, EsdfVoxel{});
        }
        SumT update{};
        bool visited = false;
        if (sum_cells.words) {
          visited = sum_cells.take(key, &update);
        } else if (const uint64_t units = free_space_sums[key]) {
          free_space_sums[key] = 0;
          tsdf_detail::add_free_space_sum(update, units, truncation);
          visited = true;
        }
        if (visited && slot == kInvalidSlot) ++rejected;
        if (visited && slot != kInvalidSlot) {
          ++written;
          merge_into_voxel(index, update);
        }
        // Every listed block has a kept visit, so it changes (the band's writes mark theirs too).
        if ((i & (voxels_per_block - 1)) == 0 && slot != kInvalidSlot)
          block_changed[slot] = kAllPending;
      }
      const uint32_t lanes = warp_lanes();
      const uint32_t written_in_warp = warp_sum(lanes, written);
      const uint32_t rejected_in_warp = warp_sum(lanes, rejected);
      if (warp_lane() == warp_first_lane(lanes)) {
        if (written_in_warp)
          atomic_add(&counts_on_device[tsdf_detail::kFreeOnlyVoxelsWord], written_in_warp);
        if (rejected_in_warp)
          atomic_add(&counts_on_device[tsdf_detail::kFreeRejectedWord], rejected_in_warp);
      }
    });
    if (tally_stripes) scratch.merge_tally_clean = true;
  };
  if (free_out_of_range) {
    if (pass_counted_on_device) {
      write_listed_cells(true, block_bound, counts_on_device + tsdf_detail::kBlockCountWord, 0u,
                         pool_slots);
    } else if (activation_deferred) {
      write_listed_cells(true, counts.blocks, nullptr, 0u, pool_slots);
    } else {
      write_listed_cells(true, counts.blocks, nullptr, 0u, kInvalidSlot);
    }
    profile.mark(sum_every_visit ? "5 write summed voxels" : "5b free-space voxels");
  }
  tsdf_detail::reset_merge_tally(backend, scratch, stream);  // for the next frame

  counts = tsdf_detail::read_frame_counts(scratch, stream);  // waits for the writes too
  scratch.last_listed_blocks = counts.blocks;

  if (activation_deferred) {
    activation = map.blocks().finish_in_kernel_activation(counts.new_blocks, counts.rejected_blocks,
                                                          counts.full_blocks);
    stats.blocks_allocated = activation.num_new;
    if (map.blocks().slot_count() > pool_slots) {  // new slots past the pool: grown, then written
      map.ensure_pool_capacity(stream);
      write_listed_cells(false, counts.blocks, nullptr, pool_slots, kInvalidSlot);
      counts = tsdf_detail::read_frame_counts(scratch, stream);
    }
  }
  if (free_out_of_range) scratch.fixed_point_sums_clean = true;

  if (band.keys && counts.band_records > band_bound) {
    throw Error("TSDF integrator: " + std::to_string(counts.band_records) +
                " band visits in one frame, more than the " + std::to_string(band_bound) +
                " its rays allow (internal error; please report it)");
  }
  const tsdf_detail::DroppedRecords dropped = tsdf_detail::dropped_records(
      counts, live_records ? static_cast<int64_t>(counts.band_records) : record_count);
  stats.voxels_updated = dropped.kept_voxels + counts.free_only_voxels;
  stats.voxels_out_of_range = (grouped ? grouping.out_of_range : dropped.out_of_range) +
                              counts.free_out_of_range + counts.free_rejected;
  if (activation.num_out_of_range + activation.num_failed_full > 0 && record_count > 0) {
    // Rare: count the voxels whose block the hash table rejected (outside its key range, or full).
    scratch.counts.resize_discard(record_count);
    uint32_t* rejected = scratch.counts.data();
    parallel_for(backend, stream, record_count, [=] COVOX_HD(int64_t j) {
      const KeyT key = record_keys[j];
      const bool voxel_start = j == 0 || key != record_keys[j - 1];
      rejected[j] =
          voxel_start && key < out_of_range_key && record_slots.slot_of(j, key) == kInvalidSlot
              ? 1u
              : 0u;
    });
    stats.voxels_out_of_range += count_if(backend, stream, rejected, record_count,
                                          [] COVOX_HD(uint32_t r) { return r != 0; });
  }
  profile.mark("5 sum and write voxels");
}

namespace tsdf_detail {
// Steps 2b to 5 with the frame's record types: 32-bit keys when its box allows, colour visits
// when it has colour.
template <class Backend>
void fuse_frame(Backend backend, const TsdfIntegratorConfig& config,
                const tsdf::FrameUpdates& frame, bool has_color, int64_t ray_count, TsdfMap& map,
                TsdfScratchBuffers& scratch, IntegrationStats& stats, StageProfiler::Scope& profile,
                const Stream& stream) {
  const bool short_keys = frame.codec.key_bits <= 32;
  if (has_color && short_keys) {
    tsdf_fuse_updates<uint32_t, tsdf::ColorVisit>(backend, config, frame, ray_count, map, scratch,
                                                  stats, profile, stream);
  } else if (has_color) {
    tsdf_fuse_updates<uint64_t, tsdf::ColorVisit>(backend, config, frame, ray_count, map, scratch,
                                                  stats, profile, stream);
  } else if (short_keys) {
    tsdf_fuse_updates<uint32_t, tsdf::DistanceUpdate>(backend, config, frame, ray_count, map,
                                                      scratch, stats, profile, stream);
  } else {
    tsdf_fuse_updates<uint64_t, tsdf::DistanceUpdate>(backend, config, frame, ray_count, map,
                                                      scratch, stats, profile, stream);
  }
}
}  // namespace tsdf_detail

namespace tsdf_detail {
// A frame's points: `cloud`, or with `depth_image` that image's points, read in place by the
// merged method (tsdf_merge_rays; `cloud` then names scratch.points / scratch.colors, which the
// merge writes) and unprojected first by the simple method.
template <class Backend>
IntegrationStats integrate_frame(Backend backend, const TsdfIntegratorConfig& config, TsdfMap& map,
                                 const PointCloudView& cloud,
                                 const tsdf::DepthImagePoints* depth_image,
                                 const Eigen::Isometry3d& T_map_sensor, TsdfScratchBuffers& scratch,
                                 const Stream& stream) {
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
    if (depth_image) {
      tsdf_unproject_depth(backend, *depth_image, scratch, stream);
      profile.mark("0 unproject");
    }
    // Why points did or did not become rays, and the box of voxels their own rays traverse.
    tally = transform_reduce(backend, stream, points, n,
                             tsdf_detail::TallyPoint{ray_parameters, inverse_voxel_size},
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
    const tsdf::MergeKeys merge_keys =
        tsdf::make_merge_keys(ray_parameters.T_world_sensor.translation, config.max_ray_length_m,
                              voxel_size, voxels_per_side);
    tally = tsdf_merge_rays(backend, ray_parameters, merge_keys, cloud, colors, intensities,
                            grey_per_intensity, scratch, stream, depth_image);
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
  if (has_color && ray_count >= static_cast<int64_t>(tsdf::ColorVisit::kBandVisitBit)) {
    throw Error("TSDF integrator: " + std::to_string(ray_count) +
                " rays in one coloured frame, at most 2^31 - 1 fit a visit record's ray index");
  }
  const tsdf::FrameKeyCodec codec =
      tsdf::make_frame_key_codec(tally.low_voxel(), tally.high_voxel(), voxels_per_side);
  // Every ray has at most voxels / kVoxelsPerPiece + 1 pieces: a bound known without a read-back.
  const int64_t piece_bound = total_updates / tsdf::kVoxelsPerPiece + ray_count;
  tsdf::RaySegment* rays = scratch.rays.data();
  // (each ray's piece count was written with the ray, and a 0 after the last ray)
  const uint32_t* ray_pieces = scratch.counts.data();
  if (tsdf_detail::frame_sums_every_visit(config, Backend::kDevice, codec, total_updates,
                                          has_color)) {
    // Every visit summed: the rays are walked in groups (tsdf_traverse.h, RayGroups), each group
    // in as many levels as the longest ray has pieces (from the tally), without a piece table.
    tsdf::FrameUpdates frame{codec,       total_updates,
                             0,           nullptr,
                             nullptr,     nullptr,
                             rays,        colors,
                             intensities, grey_per_intensity,
                             ray_weights, inverse_voxel_size,
                             voxel_size,  weight_parameters};
    frame.walks_ray_groups = true;
    frame.ray_pieces = ray_pieces;
    frame.most_ray_pieces = static_cast<uint32_t>(tally.most_pieces);
    frame.ray_count = ray_count;
    profile.mark("2a ray groups");
    tsdf_detail::fuse_frame(backend, config, frame, has_color, ray_count, map, scratch, stats,
                            profile, stream);
    return stats;
  }
  scratch.offsets.resize_discard(ray_count + 1);
  exclusive_scan(backend, stream, ray_pieces, ray_count + 1, scratch.offsets.data());
  const uint32_t* first_piece = scratch.offsets.data();
  const uint32_t* piece_total = first_piece + ray_count;  // on the device
  scratch.pieces.resize_discard(piece_bound);
  scratch.piece_offsets.resize_discard(piece_bound);
  tsdf::RayPiece* pieces = scratch.pieces.data();
  // The piece table (each piece's ray and index) and each piece's voxel count, scanned into the
  // pieces' first records; the counts past the last piece are zero for the scan over the bound.
  const Index3D* piece_first_voxels = nullptr;
  if constexpr (Backend::kDevice == Device::kCpu) {
    scratch.piece_voxels.resize_discard(piece_bound);
    uint32_t* piece_voxels = scratch.piece_voxels.data();
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
      tsdf::for_each_ray_piece(rays[i], count, inverse_voxel_size,
                               [&](uint32_t k, const Index3D& first, uint32_t voxels) {
                                 const uint32_t p = first_piece[i] + k;
                                 pieces[p] = tsdf::RayPiece{static_cast<uint32_t>(i), k, count};
                                 firsts[p] = first;
                                 piece_voxels[p] = voxels;
                               });
    });
    exclusive_scan(backend, stream, piece_voxels, piece_bound, scratch.piece_offsets.data());
  } else {
    // Not on the GPU, where both versions tried cost more than they saved (H100, KITTI 50 m
    // rays of about 30 pieces, this step 85-92 -> 140-145 us per scan): the loop over a ray's
    // cuts serialises long rays, and a piece table carrying the cut voxels doubles its strided
    // writes. One thread per piece instead: it finds its ray by a binary search of the rays'
    // first pieces (a few kilobytes, cached), writes its table entry and counts its own voxels;
    // the traverse computes the cuts again. (A loop per ray listing its pieces, then a kernel
    // per piece: 15 us more per 7-Scenes 5 cm frame, H100, 2026-11-24.)
    // The table is written by the scan of the pieces' voxel counts, which computes them (one
    // launch instead of a kernel and a scan; one piece per thread, as the binary searches are
    // chains of dependent loads: with 8 per thread this scan took 18.9 us of a 7-Scenes 5 cm
    // frame on the H100, against 6.3 + 5.8 us for the kernel and the scan before it).
    exclusive_scan_of<1>(
        backend, stream, piece_bound,
        [=] COVOX_HD(int64_t p) -> uint32_t {
          if (p >= *piece_total) return 0u;
          const uint32_t piece = static_cast<uint32_t>(p);
          // the last ray whose first piece is at or before p (rays without pieces share the next
          // one's)
          const uint32_t i =
              static_cast<uint32_t>(lower_bound_index(first_piece, ray_count, piece + 1u) - 1);
          const uint32_t index = piece - first_piece[i];
          const uint32_t count = ray_pieces[i];
          pieces[p] = tsdf::RayPiece{i, index, count};
          return tsdf::ray_piece_voxel_count(rays[i], index, count, inverse_voxel_size);
        },
        scratch.piece_offsets.data());
  }
  profile.mark("2a ray pieces");

  const tsdf::FrameUpdates frame{codec,       total_updates,      piece_bound, piece_total,
                                 pieces,      piece_first_voxels, rays,        colors,
                                 intensities, grey_per_intensity, ray_weights, inverse_voxel_size,
                                 voxel_size,  weight_parameters};
  tsdf_detail::fuse_frame(backend, config, frame, has_color, ray_count, map, scratch, stats,
                          profile, stream);
  return stats;
}
}  // namespace tsdf_detail

template <class Backend>
IntegrationStats tsdf_integrate_points(Backend backend, const TsdfIntegratorConfig& config,
                                       TsdfMap& map, const PointCloudView& cloud,
                                       const Eigen::Isometry3d& T_map_sensor,
                                       TsdfScratchBuffers& scratch, const Stream& stream) {
  return tsdf_detail::integrate_frame(backend, config, map, cloud, nullptr, T_map_sensor, scratch,
                                      stream);
}

template <class Backend>
IntegrationStats tsdf_integrate_depth_image(Backend backend, const TsdfIntegratorConfig& config,
                                            TsdfMap& map, const tsdf::DepthImagePoints& image,
                                            const Eigen::Isometry3d& T_map_camera,
                                            TsdfScratchBuffers& scratch, const Stream& stream) {
  const int64_t pixels = image.pixels();
  // The points (and colours) are written where the view names them: by the merge, or by the
  // unprojection before the simple method's first kernel.
  scratch.points.resize_discard(pixels);
  if (image.colors) scratch.colors.resize_discard(pixels);
  const PointCloudView cloud{scratch.points.data(), image.colors ? scratch.colors.data() : nullptr,
                             pixels};
  return tsdf_detail::integrate_frame(backend, config, map, cloud, &image, T_map_camera, scratch,
                                      stream);
}

template <class Backend>
void tsdf_unproject_depth(Backend backend, const tsdf::DepthImagePoints& image,
                          TsdfScratchBuffers& scratch, const Stream& stream) {
  const int64_t pixels = image.pixels();
  scratch.points.resize_discard(pixels);
  Vec3f* points = scratch.points.data();
  Rgb8* colors = nullptr;
  if (image.colors) {
    scratch.colors.resize_discard(pixels);
    colors = scratch.colors.data();
  }
  // One thread per place in tile order: the stores are contiguous, the reads 32 pixels of a tile.
  parallel_for(backend, stream, pixels, [=] COVOX_HD(int64_t place) {
    const int64_t pixel = image.pixel_at(place);
    points[place] = image.point(pixel);
    if (colors) colors[place] = image.colors[pixel];
  });
}

#define COVOX_INSTANTIATE_TSDF_INTEGRATOR(Backend)                                    \
  template IntegrationStats tsdf_integrate_points<Backend>(                           \
      Backend, const TsdfIntegratorConfig&, TsdfMap&, const PointCloudView&,          \
      const Eigen::Isometry3d&, TsdfScratchBuffers&, const Stream&);                  \
  template IntegrationStats tsdf_integrate_depth_image<Backend>(                      \
      Backend, const TsdfIntegratorConfig&, TsdfMap&, const tsdf::DepthImagePoints&,  \
      const Eigen::Isometry3d&, TsdfScratchBuffers&, const Stream&);                  \
  template void tsdf_unproject_depth<Backend>(Backend, const tsdf::DepthImagePoints&, \
                                              TsdfScratchBuffers&, const Stream&);

}  // namespace covox

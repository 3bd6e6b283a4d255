#pragma once
// Stage 5 of a TSDF frame: each voxel written once, the weighted average of the voxel and the
// frame's sum of its visits. The records' runs are summed (core/run_sums.h) and each sum, with
// the voxel's free-space sum, goes straight into the voxel's write (WriteVoxelRun); a pass over
// the listed blocks' cells then writes the voxels whose visits were all summed in fixed point
// (WriteListedCells: with every visit summed, every voxel).
#include <algorithm>
#include <cstdint>

#include "covoxslam/core/parallel.h"
#include "covoxslam/core/run_sums.h"
#include "covoxslam/core/warp_reduce.h"
#include "covoxslam/integrators/internal/tsdf_stage_blocks.h"
#include "covoxslam/integrators/internal/tsdf_stage_group_records.h"
#include "covoxslam/integrators/internal/tsdf_stage_merge_rays.h"

namespace covox::integrators::tsdf {

// A voxel's free-space sum (fixed point, tsdf_kernels.h) added to its band visits' sum.
template <class SumT>
COVOX_HD_INLINE void add_free_space_sum(SumT& sum, uint64_t units, float truncation) {
  const DistanceUpdate free = free_space_update(weight_of_units(units), truncation);
  sum.weighted_distance += free.weighted_distance;
  sum.weight += free.weight;
}

// The colour blend: a frame without colour (DistanceUpdate) has none to blend.
template <class ColorView>
COVOX_HD_INLINE void blend_color(const ColorView&, int64_t, const DistanceUpdate&, float) {}
template <class ColorView>
COVOX_HD_INLINE void blend_color(const ColorView& color_view, int64_t index,
                                 const VoxelUpdate& update, float max_weight) {
  if (update.color_weight <= 0.0f) return;
  map::ColorVoxel color = color_view.load(index);
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
  map::TsdfMap::TsdfStorage::View tsdf_view;
  map::TsdfMap::ColorStorage::View color_view;
  float truncation;
  float max_weight;
  template <class SumT>
  COVOX_HD_INLINE void operator()(int64_t index, const SumT& update) const {
    map::TsdfVoxel voxel = tsdf_view.load(index);
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

// The slot of a kept record's block, from the block's rank among the listed blocks: by its number
// in the frame's box (blocks listed from the marks: the scan of the marks) or by the record's place
// among the sorted records' blocks (one load per voxel write, rather than a kernel writing each
// box block's slot beforehand).
struct RecordSlots {
  FrameKeyCodec codec;
  const uint32_t* box_ranks;    // the scan of the box blocks' marks, or null
  const uint32_t* slots;        // per listed block
  const uint32_t* block_ranks;  // sorted records: the rank of each record's block
  const uint32_t* block_flags;  //   and whether the record starts it
  COVOX_HD_INLINE uint32_t slot_of(int64_t j, uint64_t key) const {
    return box_ranks ? slots[box_ranks[codec.block_part(key)]]
                     : slots[block_ranks[j] + block_flags[j] - 1];
  }
};
inline RecordSlots record_slots(const FrameKeyCodec& codec, const BlockListing& listing) {
  return RecordSlots{codec, listing.box_ranks, listing.slots, listing.record_block_ranks,
                     listing.record_block_flags};
}

// consume_run_sums' consumer: a voxel's run of records, given the index of its first record and
// the sum of its updates, written once; the runs of dropped records (sorted last) only leave
// their first index, from which their counts follow. With free-space sums the voxel's free-space
// sum is added (and taken, so the pass over the cells skips it).
template <class KeyT, class SumT>
struct WriteVoxelRun {
  const KeyT* record_keys;
  KeyT out_of_range_key;
  KeyT zero_weight_key;
  FrameResults* results;
  uint64_t* free_space_sums;
  float truncation;
  RecordSlots record_slots;
  uint8_t* block_changed;
  VoxelMerge merge_into_voxel;
  int64_t voxels_per_block;
  COVOX_HD_INLINE void operator()(int64_t j, const SumT& band_update) const {
    const KeyT key = record_keys[j];
    if (key >= out_of_range_key) {
      note_dropped_run(results, key == zero_weight_key, j);
      return;
    }
    SumT update = band_update;
    if (free_space_sums) {  // the voxel's free-space visits (taken, so the pass below skips it)
      const uint64_t units = free_space_sums[key];
      if (units != 0) {
        free_space_sums[key] = 0;
        add_free_space_sum(update, units, truncation);
      }
    }
    const FrameKeyCodec& codec = record_slots.codec;
    const uint32_t slot = record_slots.slot_of(j, key);
    if (slot == map::kInvalidSlot) return;
    if (j == 0 || codec.block_part(record_keys[j - 1]) != codec.block_part(key)) {
      block_changed[slot] = map::kAllPending;  // once per block: its first voxel
    }
    if (update.weight <= 0.0f) return;
    merge_into_voxel(static_cast<int64_t>(slot) * voxels_per_block + codec.voxel_in_block(key),
                     update);
  }
};

// Stage 5a (frames that keep records): each voxel's records summed and written once. With
// free-space sums the sorted records are the band's, then zero-weight fill up to the bound: only
// the band's are read (their count is on the device).
template <class KeyT, class ValueT, class Backend>
void write_record_voxels(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                         const FrameUpdates& updates, const FrameRecords<KeyT, ValueT>& records,
                         const BlockListing& listing) {
  using SumT = VisitSumOf<ValueT>;
  TsdfScratchBuffers& scratch = frame.scratch;
  map::TsdfMap& map = frame.map;
  const float truncation = frame.config.truncation_distance_m;
  const KeyT out_of_range_key = static_cast<KeyT>(plan.codec.out_of_range_key);
  FrameResults* results = scratch.results.data();
  const WriteVoxelRun<KeyT, SumT> write_voxel{
      records.record_keys,
      out_of_range_key,
      static_cast<KeyT>(plan.codec.zero_weight_key),
      results,
      records.free_space_sums,
      truncation,
      record_slots(plan.codec, listing),
      map.block_changed().data(),
      VoxelMerge{map.tsdf().view(), map.color().view(), truncation, frame.config.max_weight},
      map.voxels_per_block()};
  uint32_t* runs_counted = &results->runs;
  const uint32_t* live_records = records.band.keys ? &results->band_records : nullptr;
  Buffer<uint64_t>& tile_parts = scratch.records.run_tile_parts;
  if (records.grouped) {  // one record per voxel, none dropped
    consume_run_sums<SumT>(frame.backend, frame.stream, records.record_keys, records.record_count,
                           ArrayTerm<SumT>{records.merged_updates}, MergeUpdates(), write_voxel,
                           tile_parts, runs_counted);
  } else if constexpr (std::is_same<ValueT, ColorVisit>::value) {
    const VoxelUpdateOfRecord<KeyT> update_of{updates, records.keys, records.values,
                                              out_of_range_key, truncation};
    consume_run_sums<SumT>(frame.backend, frame.stream, records.record_keys, records.record_count,
                           update_of, MergeUpdates(), write_voxel, tile_parts, runs_counted,
                           live_records);
  } else {
    consume_run_sums<SumT>(frame.backend, frame.stream, records.record_keys, records.record_count,
                           ArrayTerm<SumT>{records.values}, MergeUpdates(), write_voxel, tile_parts,
                           runs_counted, live_records);
  }
}

// Threads for a pass whose work items the host knows only by a bound (`bound`: `extra` items
// and the cells of the blocks the frame lists, whose count is on the device), in a grid-stride
// loop over the count. The bound is loose (the frame's box's blocks), and threads past the count
// cost their launch; the listed blocks change little from frame to frame, so the pass starts 1.5
// times as many threads as the last frame's cells (`last_cells`, negative when unknown: then at
// most 2^20) and the loop covers any more.
inline int64_t counted_pass_threads(int64_t bound, int64_t extra, int64_t last_cells) {
  const int64_t wanted =
      last_cells >= 0 ? extra + last_cells + last_cells / 2 + 1024 : int64_t(1) << 20;
  return std::max<int64_t>(1, std::min(bound, wanted));
}

// The pass over the listed blocks' cells: every cell read (and cleared), a new block's voxels
// cleared first when every visit is summed, the voxels with summed visits written. A pass writes
// the blocks whose slots lie in [slot_begin, slot_end) (and, the first, counts the rejected
// blocks' visited cells), leaving the others' cells for the second. The first pass also hands
// over the count of summed visits outside the box and the in-kernel activation's totals, and
// clears the merge's tally stripes, if any (reset_merge_tally): `extra` items after the cells.
// `device_blocks`: the listed blocks' count on the device, the bound then only its bound (a
// grid-stride loop covers the count).
template <class SumT>
struct WriteListedCells {
  const uint32_t* device_blocks;
  int64_t voxels_per_block;
  int64_t bound;
  int64_t extra;
  int64_t threads;
  FrameResults* results;
  uint64_t* free_out_of_range;
  bool hands_over_activation;
  map::BlockActivator activator;
  MergeTallyStripe* tally_stripes;
  bool first_pass;
  uint32_t slot_begin;
  uint32_t slot_end;
  const uint32_t* slots;
  const Index3D* block_indices;
  const uint8_t* is_new;
  FrameKeyCodec codec;
  bool sums_every_visit;
  VoxelSumCells sum_cells;
  uint64_t* free_space_sums;
  float truncation;
  map::TsdfMap::TsdfStorage::View tsdf_view;
  map::TsdfMap::ColorStorage::View color_view;
  map::TsdfMap::EsdfStorage::View esdf_view;
  VoxelMerge merge_into_voxel;
  uint8_t* block_changed;

  // Extra item i (cells: the first extra item's index): the hand-over, then the tally's stripes.
  COVOX_HD_INLINE void extra_item(int64_t i, int64_t cells) const {
    if (i != cells) {
      tally_stripes[i - cells - 1].reset();
      return;
    }
    results->free_out_of_range = static_cast<uint32_t>(*free_out_of_range);
    *free_out_of_range = 0;
    if (hands_over_activation) {
      uint32_t totals[3];
      activator.hand_over_totals(totals);
      results->new_blocks = totals[0];
      results->rejected_blocks = totals[1];
      results->table_full_blocks = totals[2];
    }
  }
  // Cell i: the (i >> voxel_bits)-th listed block's voxel (voxels_per_block = 2^voxel_bits: no
  // 64-bit division).
  COVOX_HD_INLINE void write_cell(int64_t i, uint32_t* written, uint32_t* rejected) const {
    const int voxel_bits = codec.voxel_bits;
    const int32_t voxels_per_side = codec.voxels_per_side;
    const int64_t b = i >> voxel_bits;
    const uint32_t slot = slots[b];
    if (slot == map::kInvalidSlot ? !first_pass : (slot < slot_begin || slot >= slot_end)) return;
    const Index3D block = block_indices[b];
    const uint64_t block_key = codec.key(
        Index3D(block.x * voxels_per_side, block.y * voxels_per_side, block.z * voxels_per_side));
    const uint64_t key = block_key | static_cast<uint64_t>(i & (voxels_per_block - 1));
    const int64_t index =
        static_cast<int64_t>(slot) * voxels_per_block + (key & ((uint64_t(1) << voxel_bits) - 1));
    if (sums_every_visit && slot != map::kInvalidSlot &&
        is_new[b]) {  // a new block may reuse an erased one's slot
      tsdf_view.store(index, map::TsdfVoxel{});
      color_view.store(index, map::ColorVoxel{});
      esdf_view.store(index, map::EsdfVoxel{});
    }
    SumT update{};
    bool visited = false;
    if (sum_cells.words) {
      visited = sum_cells.take(key, &update);
    } else if (const uint64_t units = free_space_sums[key]) {
      free_space_sums[key] = 0;
      add_free_space_sum(update, units, truncation);
      visited = true;
    }
    if (visited && slot == map::kInvalidSlot) ++*rejected;
    if (visited && slot != map::kInvalidSlot) {
      ++*written;
      merge_into_voxel(index, update);
    }
    // Every listed block has a kept visit, so it changes (the band's writes mark theirs too).
    if ((i & (voxels_per_block - 1)) == 0 && slot != map::kInvalidSlot)
      block_changed[slot] = map::kAllPending;
  }
  COVOX_HD_INLINE void operator()(int64_t t) const {
    // the cells first (a warp's 32 cells aligned), then the extra items
    const int64_t cells =
        device_blocks ? static_cast<int64_t>(*device_blocks) * voxels_per_block : bound - extra;
    uint32_t written = 0, rejected = 0;
    for (int64_t i = t; i < cells + extra; i += threads) {
      if (i >= cells) {
        extra_item(i, cells);
        continue;
      }
      write_cell(i, &written, &rejected);
    }
    const uint32_t lanes = warp_lanes();
    const uint32_t written_in_warp = warp_sum(lanes, written);
    const uint32_t rejected_in_warp = warp_sum(lanes, rejected);
    if (warp_lane() == warp_first_lane(lanes)) {
      if (written_in_warp) atomic_add(&results->free_only_voxels, written_in_warp);
      if (rejected_in_warp) atomic_add(&results->free_rejected, rejected_in_warp);
    }
  }
};

// One pass of WriteListedCells over `blocks` listed blocks (with `device_blocks`, a bound).
template <class KeyT, class ValueT, class Backend>
void write_listed_cells(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                        const FrameRecords<KeyT, ValueT>& records, const BlockListing& listing,
                        bool first_pass, int64_t blocks, const uint32_t* device_blocks,
                        uint32_t slot_begin, uint32_t slot_end) {
  TsdfScratchBuffers& scratch = frame.scratch;
  map::TsdfMap& map = frame.map;
  const int64_t voxels_per_block = map.voxels_per_block();
  const float truncation = frame.config.truncation_distance_m;
  // (the pools' views taken now: the second pass runs after they grew)
  const auto tsdf_view = map.tsdf().view();
  const auto color_view = map.color().view();
  MergeTallyStripe* tally_stripes = first_pass ? merge_tally_to_reset(scratch.merge) : nullptr;
  const int64_t extra = first_pass ? 1 + (tally_stripes ? kMergeTallyStripes : 0) : 0;
  const int64_t bound = extra + blocks * voxels_per_block;
  const int64_t threads =
      device_blocks
          ? counted_pass_threads(bound, extra, scratch.blocks.last_listed * voxels_per_block)
          : bound;
  const WriteListedCells<VisitSumOf<ValueT>> kernel{
      device_blocks,
      voxels_per_block,
      bound,
      extra,
      threads,
      scratch.results.data(),
      records.free_out_of_range,
      first_pass && listing.activates_while_listing,
      listing.activator,
      tally_stripes,
      first_pass,
      slot_begin,
      slot_end,
      listing.slots,
      listing.indices,
      listing.is_new,
      plan.codec,
      plan.sums_every_visit(),
      records.sum_cells,
      records.free_space_sums,
      truncation,
      tsdf_view,
      color_view,
      map.esdf().view(),
      VoxelMerge{tsdf_view, color_view, truncation, frame.config.max_weight},
      map.block_changed().data()};
  parallel_for(frame.backend, frame.stream, threads, kernel);
  if (tally_stripes) scratch.merge.tally_clean = true;
}

// Stage 5b (frames that sum visits): the first pass over the listed blocks' cells: counted on the
// device, or of the blocks read back; with the activation deferred, only the blocks whose slots
// the pool already holds.
template <class KeyT, class ValueT, class Backend>
void write_summed_cells(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                        const FrameRecords<KeyT, ValueT>& records, const BlockListing& listing) {
  if (listing.pass_counted_on_device) {
    write_listed_cells(frame, plan, records, listing, true, listing.bound,
                       &frame.scratch.results.data()->blocks, 0u, listing.pool_slots);
  } else if (listing.activates_while_listing) {
    write_listed_cells(frame, plan, records, listing, true, listing.results.blocks, nullptr, 0u,
                       listing.pool_slots);
  } else {
    write_listed_cells(frame, plan, records, listing, true, listing.results.blocks, nullptr, 0u,
                       map::kInvalidSlot);
  }
}

// Stage 5c: the frame's one wait, its results read back. A frame that activated its blocks while
// listing them finishes the activation with their totals, and any block whose new slot lies past
// the voxel pool (rare: the pool grows geometrically) is written by a second pass once the pool
// has grown. Returns the new blocks.
template <class KeyT, class ValueT, class Backend>
int64_t read_frame_end(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                       const FrameRecords<KeyT, ValueT>& records, BlockListing* listing) {
  TsdfScratchBuffers& scratch = frame.scratch;
  listing->results = read_frame_results(scratch.results, frame.stream);  // waits for the writes
  scratch.blocks.last_listed = listing->results.blocks;
  if (listing->activates_while_listing) {
    const FrameResults& results = listing->results;
    listing->activation = frame.map.blocks().finish_in_kernel_activation(
        results.new_blocks, results.rejected_blocks, results.table_full_blocks);
    if (frame.map.blocks().slot_count() > listing->pool_slots) {  // past the pool: grown, written
      frame.map.ensure_pool_capacity(frame.stream);
      write_listed_cells(frame, plan, records, *listing, false, listing->results.blocks, nullptr,
                         listing->pool_slots, map::kInvalidSlot);
      listing->results = read_frame_results(scratch.results, frame.stream);
    }
  }
  if (plan.sums_visits()) scratch.grids.sums_clean = true;
  return listing->activation.num_new;
}

}  // namespace covox::integrators::tsdf

#pragma once
// Stage 2b of a TSDF frame: every ray walks its voxels (tsdf_traverse.h). Each visit becomes a
// record (key, value), or is added to its voxel's fixed-point cell over the frame's box (the
// plan's VisitMerging); the walk also marks the blocks its kept visits fall in.
#include <cstdint>
#include <type_traits>
#include <utility>

#include "covoxslam/integrators/internal/tsdf_frame_plan.h"
#include "covoxslam/integrators/internal/tsdf_group_updates_cpu.h"
#include "covoxslam/integrators/internal/tsdf_traverse.h"

namespace covox::integrators::tsdf {

// A voxel's sum of visits: with colour (the records are ColorVisit) a VoxelUpdate.
template <class ValueT>
using VisitSumOf =
    std::conditional_t<std::is_same<ValueT, ColorVisit>::value, VoxelUpdate, DistanceUpdate>;

// What the walk leaves for the later stages: the records (device memory) and the box's grids.
template <class KeyT, class ValueT>
struct FrameRecords {
  uint32_t* block_marks = nullptr;  // with the plan's marks_blocks
  // With free-space sums: one weight per key of the box. With every visit summed: the cells.
  uint64_t* free_space_sums = nullptr;
  VoxelSumCells sum_cells;
  uint64_t* free_out_of_range = nullptr;  // the word past the box's cells: visits summed outside it
  // The records and their sort's scratch (swapped as the records move).
  KeyT* keys = nullptr;
  KeyT* keys_alt = nullptr;
  ValueT* values = nullptr;
  ValueT* values_alt = nullptr;
  // With free-space sums, the band's records, compacted in visit order into the first band_bound
  // places of the scratch arrays (then swapped in), so that the sort and the reduction see a bound
  // the host knows without a read-back.
  BandRecords<KeyT, ValueT> band;
  // What stage 5 reads: the records' keys (sorted, or the CPU twin's merged voxels) and how many.
  const KeyT* record_keys = nullptr;
  int64_t record_count = 0;
  // The CPU twin's grouping: one merged record per voxel, with its sum.
  bool grouped = false;
  VisitSumOf<ValueT>* merged_updates = nullptr;
  GroupCounts grouping;
};

// The box's marks (all clear, one past them for the scan's total), the fixed-point grid the plan
// asks for (all clear, one word past its cells counting the visits summed outside the box), the
// record arrays, and the frame's results on the device.
template <class KeyT, class ValueT, class Backend>
FrameRecords<KeyT, ValueT> prepare_records(const FrameContext<Backend>& frame,
                                           const TsdfFramePlan& plan) {
  TsdfScratchBuffers& scratch = frame.scratch;
  TsdfScratchBuffers::BoxGrids& grids = scratch.grids;
  FrameRecords<KeyT, ValueT> records;
  if (plan.marks_blocks) {
    records.block_marks =
        clean_frame_scratch(grids.block_marks, grids.block_marks_clean,
                            static_cast<size_t>(plan.box_blocks) + 1, frame.stream);
  }
  if (plan.sums_every_visit()) {
    records.sum_cells.words = clean_frame_scratch(
        grids.sums, grids.sums_clean, plan.box_cells * plan.cell_words + 1, frame.stream);
    records.sum_cells.stride = plan.cell_words;
    records.sum_cells.truncation = frame.config.truncation_distance_m;
    records.free_out_of_range = records.sum_cells.words + plan.box_cells * plan.cell_words;
  } else if (plan.sums_free_space()) {
    records.free_space_sums =
        clean_frame_scratch(grids.sums, grids.sums_clean, plan.box_cells + 1, frame.stream);
    records.free_out_of_range = records.free_space_sums + plan.box_cells;
  }
  auto key_buffers = scratch.records.key_buffers<KeyT>();
  for (int k = 0; k < 2; ++k) key_buffers[k]->resize_discard(plan.record_space());
  records.keys = key_buffers[0]->data();
  records.keys_alt = key_buffers[1]->data();
  auto value_buffers = scratch.records.value_buffers<ValueT>();
  for (Buffer<ValueT>* buffer : value_buffers) buffer->resize_discard(plan.record_space());
  records.values = value_buffers[0]->data();
  records.values_alt = value_buffers[1]->data();
  scratch.results.resize_discard(1);
  if (plan.sums_free_space()) {
    records.band = BandRecords<KeyT, ValueT>{records.keys_alt, records.values_alt, plan.band_bound,
                                             &scratch.results.data()->band_records, nullptr};
    if constexpr (std::is_same<Backend, CpuBackend>::value) {
      scratch.records.band_ranks.resize_discard(plan.total_updates + 1);
      records.band.ranks = scratch.records.band_ranks.data();
    }
  }
  return records;
}

// Stage 2b: the walk. With every visit summed the rays are walked in groups and no record is
// kept; else the piece table is walked into the records (with free-space sums, the band's only).
template <class KeyT, class ValueT, class Backend>
void walk_visits(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                 const FrameUpdates& updates, FrameRecords<KeyT, ValueT>* records) {
  const PieceTraversal<KeyT, ValueT> traversal{updates,
                                               static_cast<KeyT>(plan.codec.zero_weight_key),
                                               frame.scratch.pieces.first_records.data(),
                                               frame.config.truncation_distance_m,
                                               records->block_marks,
                                               records->free_space_sums,
                                               records->free_out_of_range,
                                               true,
                                               records->sum_cells};
  records->record_count = plan.total_updates;  // the dropped records sort last
  if (plan.sums_every_visit()) {
    sum_ray_groups(frame.backend, frame.stream, traversal,
                   RayGroups{updates.ray_pieces, updates.most_ray_pieces, updates.ray_count,
                             ray_group_count(updates.ray_count)});
    records->record_count = 0;
  } else {
    traverse_pieces(frame.backend, frame.stream, updates.piece_bound, plan.total_updates, traversal,
                    RecordArrays<KeyT, ValueT>{records->keys, records->values}, records->band);
  }
  if (records->band.keys) {
    std::swap(records->keys, records->keys_alt);
    std::swap(records->values, records->values_alt);
    records->record_count = plan.band_bound;
  }
  records->record_keys = records->keys;
}

}  // namespace covox::integrators::tsdf

#pragma once
// Stage 3 of a TSDF frame that keeps records: the records grouped by voxel. A stable radix sort
// by key keeps each voxel's records in ray order, so the float sums that stage 5 takes are the
// same every run; records to drop (outside the key range, zero weight) sort last, one run per
// kind. The CPU twin groups them in dense per-block arrays instead (tsdf_group_updates_cpu.h):
// the same voxels and (within rounding) sums as the sort and the run sums, with a third of the
// moves; its merged records are runs of one, and none is dropped.
#include <cstdint>
#include <type_traits>

#include "covoxslam/core/radix_sort.h"
#include "covoxslam/integrators/internal/tsdf_stage_walk_visits.h"

namespace covox::integrators::tsdf {

// Stage 5's terms when the records are sums already (no colour, or the CPU twin's merged voxels).
template <class SumT>
struct ArrayTerm {
  const SumT* sums;
  COVOX_HD_INLINE SumT operator()(int64_t j) const { return sums[j]; }
};

// Stage 3 on the CPU twin, where the plan asks for it: the records moved by block to the scratch
// arrays, then summed per voxel into merged keys and sums.
template <class KeyT, class ValueT, class Backend>
void group_records_on_cpu(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                          const FrameUpdates& updates, FrameRecords<KeyT, ValueT>* records) {
  if constexpr (std::is_same<Backend, CpuBackend>::value) {
    using SumT = VisitSumOf<ValueT>;
    TsdfScratchBuffers::Records& scratch = frame.scratch.records;
    const int64_t count = records->record_count;
    Buffer<KeyT>* merged_key_buffer = scratch.key_buffers<KeyT>()[2];
    merged_key_buffer->resize_discard(count);
    KeyT* merged_keys = merged_key_buffer->data();
    if constexpr (std::is_same<ValueT, ColorVisit>::value) {
      scratch.merged_updates.resize_discard(count);
      records->merged_updates = scratch.merged_updates.data();
      const VoxelUpdateOfRecord<KeyT> update_of{updates, records->keys_alt, records->values_alt,
                                                static_cast<KeyT>(plan.codec.out_of_range_key),
                                                frame.config.truncation_distance_m};
      records->grouping = group_updates_by_voxel_cpu(
          plan.codec, records->keys, records->values, count, records->keys_alt, records->values_alt,
          merged_keys, records->merged_updates, update_of, MergeUpdates());
    } else {
      records->merged_updates = records->values;  // free once the records have moved
      records->grouping = group_updates_by_voxel_cpu(
          plan.codec, records->keys, records->values, count, records->keys_alt, records->values_alt,
          merged_keys, records->merged_updates, ArrayTerm<SumT>{records->values_alt},
          MergeUpdates());
    }
    records->record_keys = merged_keys;
    records->record_count = records->grouping.voxels;
    records->grouped = true;
  }
}

// Stage 3 elsewhere: the stable radix sort by key.
template <class KeyT, class ValueT, class Backend>
void sort_records(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                  FrameRecords<KeyT, ValueT>* records) {
  radix_sort_pairs_swapping(frame.backend, frame.stream, records->keys, records->values,
                            records->record_count, plan.codec.key_bits, records->keys_alt,
                            records->values_alt);
  records->record_keys = records->keys;  // the sort may have swapped the buffers
}

}  // namespace covox::integrators::tsdf

#pragma once
// Stage 5c of a TSDF frame, its end: the figures, from the results read back
// (tsdf_stage_write_voxels.h, read_frame_end) and, rarely, a count of the voxels whose block the
// hash table rejected.
#include <cstdint>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/integrators/internal/tsdf_stage_write_voxels.h"

namespace covox::integrators::tsdf {

// Whether record j starts a voxel whose block the hash table rejected.
template <class KeyT>
struct FlagRejectedVoxels {
  const KeyT* record_keys;
  KeyT out_of_range_key;
  RecordSlots record_slots;
  uint32_t* rejected;
  COVOX_HD_INLINE void operator()(int64_t j) const {
    const KeyT key = record_keys[j];
    const bool voxel_start = j == 0 || key != record_keys[j - 1];
    rejected[j] =
        voxel_start && key < out_of_range_key && record_slots.slot_of(j, key) == map::kInvalidSlot
            ? 1u
            : 0u;
  }
};
struct IsFlagged {
  COVOX_HD_INLINE bool operator()(uint32_t flag) const { return flag != 0; }
};

// The voxels written and dropped, into `stats`. Throws covox::Error if the band's records
// overflowed their bound (an internal error).
template <class KeyT, class ValueT, class Backend>
void count_frame_voxels(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                        const FrameRecords<KeyT, ValueT>& records, const BlockListing& listing,
                        IntegrationStats* stats) {
  const FrameResults& results = listing.results;
  if (records.band.keys && results.band_records > plan.band_bound) {
    throw Error("TSDF integrator: " + std::to_string(results.band_records) +
                " band visits in one frame, more than the " + std::to_string(plan.band_bound) +
                " its rays allow (internal error; please report it)");
  }
  const int64_t record_count = records.record_count;
  const DroppedRecords dropped = dropped_records(
      results, records.band.keys ? static_cast<int64_t>(results.band_records) : record_count);
  stats->voxels_updated = dropped.kept_voxels + results.free_only_voxels;
  stats->voxels_out_of_range =
      (records.grouped ? records.grouping.out_of_range : dropped.out_of_range) +
      results.free_out_of_range + results.free_rejected;
  const map::ActivateResult& activation = listing.activation;
  if (activation.num_out_of_range + activation.num_failed_full > 0 && record_count > 0) {
    // Rare: count the voxels whose block the hash table rejected (outside its key range, or full).
    // (The rays' piece counts are dead by now: their buffer holds the flags.)
    Buffer<uint32_t>& flags = frame.scratch.rays.pieces;
    flags.resize_discard(record_count);
    parallel_for(frame.backend, frame.stream, record_count,
                 FlagRejectedVoxels<KeyT>{records.record_keys,
                                          static_cast<KeyT>(plan.codec.out_of_range_key),
                                          record_slots(plan.codec, listing), flags.data()});
    stats->voxels_out_of_range +=
        count_if(frame.backend, frame.stream, flags.data(), record_count, IsFlagged{});
  }
}

}  // namespace covox::integrators::tsdf

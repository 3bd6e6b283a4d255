#pragma once
// The figures a TSDF frame's kernels leave on the device, read back together at the frame's end
// (one copy, one wait): a struct of 32-bit words in scratch memory of the backend's device.
#include <cstddef>
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/stream.h"

namespace covox::integrators::tsdf {

struct FrameResults {
  // The frame's distinct blocks (written by the kernel that lists them), then a queued
  // activation's totals (BlockHashTable::activate_queued's totals_out: two words): three
  // consecutive words, read back together while the records sort.
  uint32_t blocks;
  uint32_t new_blocks;
  uint32_t rejected_blocks;
  // An in-kernel activation's blocks that found the table full (counted among the rejected ones
  // by a queued activation).
  uint32_t table_full_blocks;
  // 1 + the index of the first zero-weight record (sorted last), 0: none; 1 + the index of the
  // first record outside the box (sorted before them), 0: none.
  uint32_t zero_weight_first;
  uint32_t out_of_range_first;
  // Runs of equal keys that stage 5 summed.
  uint32_t runs;
  // With fixed-point sums: the voxels that had only summed visits (with every visit summed: every
  // voxel the pass wrote), those of them in blocks the hash table rejected, and the summed visits
  // outside the box; with free-space sums, the band records kept.
  uint32_t free_only_voxels;
  uint32_t free_rejected;
  uint32_t free_out_of_range;
  uint32_t band_records;
};
static_assert(offsetof(FrameResults, new_blocks) == offsetof(FrameResults, blocks) + 4 &&
                  offsetof(FrameResults, rejected_blocks) == offsetof(FrameResults, blocks) + 8,
              "the listed blocks and the queued activation's totals are one read-back");
constexpr size_t kListedBlockWordsBytes = 3 * sizeof(uint32_t);

// One copy, one wait.
inline FrameResults read_frame_results(const Buffer<FrameResults>& results, const Stream& stream) {
  FrameResults host;
  copy_bytes(&host, Device::kCpu, results.data(), results.device(), sizeof(host), stream);
  return host;
}

// Written by one thread of the kernel that lists the blocks (before stage 5 runs). The queued
// activation's totals and the band records' count are written by their own kernels.
COVOX_HD_INLINE void start_frame_results(FrameResults* results, uint32_t blocks) {
  results->blocks = blocks;
  results->zero_weight_first = 0u;
  results->out_of_range_first = 0u;
  results->runs = 0u;
  results->free_only_voxels = 0u;
  results->free_rejected = 0u;
  results->free_out_of_range = 0u;
  results->table_full_blocks = 0u;
}

// Stage 5's consumer at the run of a dropped kind: each kind is one key, so one run and one call.
COVOX_HD_INLINE void note_dropped_run(FrameResults* results, bool zero_weight, int64_t first) {
  uint32_t* word = zero_weight ? &results->zero_weight_first : &results->out_of_range_first;
  *word = static_cast<uint32_t>(first + 1);
}

// The kept voxels and the records outside the box, from the runs and where the dropped ones start.
struct DroppedRecords {
  int64_t kept_voxels = 0;
  int64_t out_of_range = 0;
};
inline DroppedRecords dropped_records(const FrameResults& results, int64_t record_count) {
  DroppedRecords dropped;
  const int kinds = (results.zero_weight_first ? 1 : 0) + (results.out_of_range_first ? 1 : 0);
  dropped.kept_voxels = static_cast<int64_t>(results.runs) - kinds;
  if (results.out_of_range_first) {
    const int64_t end = results.zero_weight_first ? results.zero_weight_first - 1 : record_count;
    dropped.out_of_range = end - (results.out_of_range_first - 1);
  }
  return dropped;
}

}  // namespace covox::integrators::tsdf

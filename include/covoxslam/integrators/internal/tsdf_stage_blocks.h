#pragma once
// Stage 4 of a TSDF frame: its distinct blocks listed and allocated in one batch (the hash table
// sees a few hundred blocks, not one key per record), and the voxel pool grown to hold them.
// The blocks are listed from the walk's marks (before the sort), or else from the sorted records,
// block-major, where each block's records form one run. On the GPU the activation is queued for
// the blocks counted on the device (at most one per box block and per record) and its totals come
// back while the records are sorted, so the host's wait overlaps the sort; when the table might
// have to grow it needs the exact count first (activate_queued says no), and on the CPU a
// read-back costs nothing. A frame that sums every visit activates each block in the scan that
// lists it (BlockActivator, block_activator.h: no activation kernel) and reads the totals at its
// end (tsdf_stage_write_voxels.h).
#include <algorithm>
#include <cstdint>
#include <optional>

#include "covoxslam/core/memory.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/integrators/internal/tsdf_frame_results.h"
#include "covoxslam/integrators/internal/tsdf_stage_walk_visits.h"
#include "covoxslam/map/block_activator.h"

namespace covox::integrators::tsdf {

// The frame's listed blocks and their activation.
struct BlockListing {
  int64_t bound = 0;  // at most this many blocks (one per box block and per kept visit)
  Index3D* indices = nullptr;
  uint32_t* slots = nullptr;
  uint8_t* is_new = nullptr;
  // Listed from the marks: each box block's rank. From the sorted records: the rank of each
  // record's block and whether the record starts it.
  const uint32_t* box_ranks = nullptr;
  const uint32_t* record_block_ranks = nullptr;
  const uint32_t* record_block_flags = nullptr;
  bool queued = false;  // an activation queued on the device (activate_queued)
  std::optional<PendingReadBack> queued_totals;  // its totals, on their way while the sort runs
  bool activates_while_listing = false;          // an in-kernel activation (BlockActivator)
  map::BlockActivator activator;
  // With the in-kernel activation and a small frame: the pass that writes the voxels reads the
  // listed blocks' count on the device (TsdfFramePlan::defers_block_count).
  bool pass_counted_on_device = false;
  map::ActivateResult activation;
  FrameResults results{};   // the device's figures as last read back
  uint32_t pool_slots = 0;  // the slots below this one have voxels in the pool
};

// An activation that a frame began and did not finish, because an exception stopped it, is
// finished from what the device holds as the frame unwinds (BlockHashTable::
// abandon_pending_activation; a queued one's totals are the frame's): else the table would refuse
// every later frame's blocks.
class PendingActivationGuard {
 public:
  PendingActivationGuard(map::BlockHashTable& table, const uint32_t* queued_totals,
                         const Stream& stream)
      : table_(table), queued_totals_(queued_totals), stream_(stream) {}
  PendingActivationGuard(const PendingActivationGuard&) = delete;
  PendingActivationGuard& operator=(const PendingActivationGuard&) = delete;
  ~PendingActivationGuard() { table_.abandon_pending_activation(queued_totals_, stream_); }

 private:
  map::BlockHashTable& table_;
  const uint32_t* queued_totals_;
  const Stream& stream_;
};

// The listing's arrays, for at most one block per box block and per kept visit (with sums the
// records are the band's only, or none: the visits bound the blocks).
template <class KeyT, class ValueT, class Backend>
void prepare_block_listing(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                           const FrameRecords<KeyT, ValueT>& records, BlockListing* listing) {
  TsdfScratchBuffers::Blocks& scratch = frame.scratch.blocks;
  const int64_t listed_bound = plan.sums_visits() ? plan.total_updates : records.record_count;
  listing->bound = std::max<int64_t>(1, std::min<int64_t>(plan.box_blocks, listed_bound));
  scratch.indices.resize_discard(listing->bound);
  scratch.slots.resize_discard(listing->bound);
  scratch.is_new.resize_discard(listing->bound);
  listing->indices = scratch.indices.data();
  listing->slots = scratch.slots.data();
  listing->is_new = scratch.is_new.data();
}

// The listed blocks activated by the host: queued (GPU), or after reading their count.
template <class Backend>
void activate_listed_blocks(const FrameContext<Backend>& frame, BlockListing* listing) {
  FrameResults* results = frame.scratch.results.data();
  if (Backend::kDevice != Device::kCpu) {
    listing->queued = frame.map.blocks().activate_queued(
        listing->indices, &results->blocks, listing->bound, listing->slots, listing->is_new,
        &results->new_blocks, frame.stream);
  }
  if (!listing->queued) {
    listing->results = read_frame_results(frame.scratch.results, frame.stream);
    listing->activation = frame.map.blocks().activate(
        listing->indices, listing->results.blocks, listing->slots, listing->is_new, frame.stream);
  }
}

// The scan's value: whether box block b is marked.
struct IsMarkedBlock {
  const uint32_t* block_marks;
  COVOX_HD_INLINE uint32_t operator()(int64_t b) const { return block_marks[b] != 0u ? 1u : 0u; }
};
// The scan's output: as each rank is known the marked block listed at it (and, activating here,
// activated) and its mark cleared for the next frame (the scan has read it); the rank past the box
// is the count, which starts the frame's results.
struct ListMarkedBlock {
  uint32_t* marked_ranks;
  int64_t box_blocks;
  FrameResults* results;
  uint32_t* block_marks;
  FrameKeyCodec codec;
  Index3D* block_indices;
  bool activate_here;
  uint32_t* slots;
  map::BlockActivator activator;
  uint8_t* is_new;
  COVOX_HD_INLINE void operator()(int64_t b, uint32_t rank) const {
    marked_ranks[b] = rank;
    if (b == box_blocks) {
      start_frame_results(results, rank);
    } else if (block_marks[b] != 0u) {
      const Index3D block = codec.block(static_cast<uint64_t>(b) << codec.voxel_bits);
      block_indices[rank] = block;
      if (activate_here) {
        bool fresh = false;
        slots[rank] = activator.activate(block, &fresh);
        is_new[rank] = fresh ? 1u : 0u;
      }
      block_marks[b] = 0u;
    }
  }
};

// Stage 4a from the marks: the marks scanned into ranks, listed, cleared, and the blocks activated
// (in the scan itself with every visit summed, when the table allows). One launch.
template <class KeyT, class ValueT, class Backend>
void list_marked_blocks(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                        const FrameRecords<KeyT, ValueT>& records, BlockListing* listing) {
  TsdfScratchBuffers& scratch = frame.scratch;
  scratch.blocks.ranks.resize_discard(plan.box_blocks + 1);
  uint32_t* marked_ranks = scratch.blocks.ranks.data();
  listing->box_ranks = marked_ranks;
  listing->activates_while_listing =
      plan.sums_every_visit() && frame.map.blocks().begin_in_kernel_activation(
                                     listing->bound, &listing->activator, frame.stream);
  const bool activate_here = listing->activates_while_listing;
  const IsMarkedBlock is_marked{records.block_marks};
  const ListMarkedBlock list_marked{marked_ranks,        plan.box_blocks, scratch.results.data(),
                                    records.block_marks, plan.codec,      listing->indices,
                                    activate_here,       listing->slots,  listing->activator,
                                    listing->is_new};
  // An insertion is a chain of dependent probes: one block per GPU thread then.
  if (activate_here) {
    exclusive_scan_of<1>(frame.backend, frame.stream, plan.box_blocks + 1, is_marked, list_marked);
  } else {
    exclusive_scan_of(frame.backend, frame.stream, plan.box_blocks + 1, is_marked, list_marked);
  }
  if (!listing->activates_while_listing) activate_listed_blocks(frame, listing);
  scratch.grids.block_marks_clean = true;
  if (listing->queued) {
    listing->queued_totals.emplace(&scratch.results.data()->blocks, Backend::kDevice,
                                   kListedBlockWordsBytes, frame.stream);
  }
}

// Whether sorted record v starts a block (a kept record whose block differs from the one before).
template <class KeyT>
struct FlagBlockStarts {
  const KeyT* record_keys;
  int64_t record_count;
  KeyT out_of_range_key;
  FrameKeyCodec codec;
  uint32_t* flags;
  COVOX_HD_INLINE void operator()(int64_t v) const {
    const bool kept = v < record_count && record_keys[v] < out_of_range_key;
    flags[v] =
        kept && (v == 0 || codec.block_part(record_keys[v]) != codec.block_part(record_keys[v - 1]))
            ? 1u
            : 0u;
  }
};
// Each block listed at its rank by the record that starts it; the count starts the results.
template <class KeyT>
struct ListSortedBlocks {
  const uint32_t* flags;
  const uint32_t* ranks;
  const KeyT* record_keys;
  int64_t record_count;
  FrameKeyCodec codec;
  Index3D* block_indices;
  FrameResults* results;
  COVOX_HD_INLINE void operator()(int64_t v) const {
    if (flags[v]) block_indices[ranks[v]] = codec.block(record_keys[v]);
    if (v == 0) start_frame_results(results, ranks[record_count]);
  }
};

// Stage 4a from the sorted records (boxes with more blocks than records): the records' block
// starts flagged, scanned into ranks, listed, and the blocks activated.
template <class KeyT, class ValueT, class Backend>
void list_sorted_blocks(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                        const FrameRecords<KeyT, ValueT>& records, BlockListing* listing) {
  TsdfScratchBuffers& scratch = frame.scratch;
  const int64_t count = records.record_count;
  scratch.blocks.flags.resize_discard(count + 1);
  scratch.blocks.ranks.resize_discard(count + 1);
  uint32_t* flags = scratch.blocks.flags.data();
  uint32_t* ranks = scratch.blocks.ranks.data();
  listing->record_block_flags = flags;
  listing->record_block_ranks = ranks;
  parallel_for(
      frame.backend, frame.stream, count + 1,
      FlagBlockStarts<KeyT>{records.record_keys, count,
                            static_cast<KeyT>(plan.codec.out_of_range_key), plan.codec, flags});
  exclusive_scan(frame.backend, frame.stream, static_cast<const uint32_t*>(flags), count + 1,
                 ranks);
  parallel_for(frame.backend, frame.stream, count + 1,
               ListSortedBlocks<KeyT>{flags, ranks, records.record_keys, count, plan.codec,
                                      listing->indices, scratch.results.data()});
  activate_listed_blocks(frame, listing);
}

// Stage 4b/4c: the activation's totals (a frame that activated its blocks while listing them
// reads them at its end, and a small one does not even wait for its block count), then the voxel
// pool grown to the table's slots. Returns the new blocks.
template <class Backend>
int64_t finish_activation(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                          BlockListing* listing) {
  listing->pass_counted_on_device = listing->activates_while_listing && plan.defers_block_count;
  if (listing->activates_while_listing) {
    if (!listing->pass_counted_on_device) {
      listing->results = read_frame_results(frame.scratch.results, frame.stream);
    }
  } else if (listing->queued_totals) {
    uint32_t totals[3];
    listing->queued_totals->wait(totals);
    listing->results.blocks = totals[0];
    listing->activation =
        frame.map.blocks().finish_queued_activation(totals[1], totals[2], frame.stream);
  } else if (listing->queued) {  // listed after the sort: its totals come back now
    listing->results = read_frame_results(frame.scratch.results, frame.stream);
    listing->activation = frame.map.blocks().finish_queued_activation(
        listing->results.new_blocks, listing->results.rejected_blocks, frame.stream);
  }
  frame.profile.mark("4b blocks: activation totals");
  frame.map.ensure_pool_capacity(frame.stream);
  // (with the activation deferred, new slots past the pool wait for a second pass)
  listing->pool_slots =
      static_cast<uint32_t>(std::min<int64_t>(frame.map.pool_slots(), map::kInvalidSlot));
  frame.profile.mark("4c blocks: pool capacity");
  return listing->activation.num_new;
}

// A new block may reuse the slot of an erased one: its voxels cleared. (The voxel writes mark the
// blocks changed, for the ESDF and the mesh.)
struct ClearNewBlocks {
  map::TsdfMap::TsdfStorage::View tsdf_view;
  map::TsdfMap::ColorStorage::View color_view;
  map::TsdfMap::EsdfStorage::View esdf_view;
  const uint8_t* is_new;
  const uint32_t* slots;
  int64_t voxels_per_block;
  COVOX_HD_INLINE void operator()(int64_t i) const {
    const int64_t b = i / voxels_per_block;
    if (!is_new[b] || slots[b] == map::kInvalidSlot) return;
    const int64_t index = static_cast<int64_t>(slots[b]) * voxels_per_block + i % voxels_per_block;
    tsdf_view.store(index, map::TsdfVoxel{});
    color_view.store(index, map::ColorVoxel{});
    esdf_view.store(index, map::EsdfVoxel{});
  }
};

// Stage 4d (frames that keep records; with every visit summed, the pass over the cells clears
// the new blocks).
template <class Backend>
void clear_new_blocks(const FrameContext<Backend>& frame, const BlockListing& listing) {
  if (listing.activation.num_new <= 0) return;
  map::TsdfMap& map = frame.map;
  const int64_t voxels_per_block = map.voxels_per_block();
  parallel_for(frame.backend, frame.stream, int64_t(listing.results.blocks) * voxels_per_block,
               ClearNewBlocks{map.tsdf().view(), map.color().view(), map.esdf().view(),
                              listing.is_new, listing.slots, voxels_per_block});
}

}  // namespace covox::integrators::tsdf

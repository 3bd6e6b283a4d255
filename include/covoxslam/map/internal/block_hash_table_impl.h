#pragma once
// The BlockHashTable algorithms, written once over a backend tag and instantiated twice:
// src/map/block_hash_table_cpu.cpp (CpuBackend) and cuda/map/block_hash_table_cuda.cu
// (CudaBackend). Only those two files include this header. activate(keys) runs passes none of
// which waits on another thread: insert (each key probes and CASes itself into an empty bucket,
// or finds itself; the CAS winner flags "new"), rank (a scan of the flags numbers the new keys in
// input order), assign (new key r takes freed slot r from the top of the free stack, or the next
// never-used slot), the three in one launch; then gather (every key, duplicates too, reads its
// bucket's slot). A separate gather lets duplicates of a key in one batch see the winner's slot
// without spinning on it.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/map/internal/block_hash_table_ops.h"
#include "covoxslam/map/block_hash_table_state.h"

namespace covox::map {
namespace internal {

// Ranks flagged items (exclusive scan) and returns how many are flagged. `flags` must hold
// count + 1 elements: the extra one is set to 0 so that the scan's last element is the total,
// read back with one small copy.
template <class Backend>
int64_t rank_flags(Backend backend, const Stream& stream, Buffer<uint32_t>& flags,
                   Buffer<uint32_t>* ranks, int64_t count) {
  if (count == 0) return 0;
  set_bytes(flags.data() + count, flags.device(), 0, sizeof(uint32_t), stream);
  ranks->resize_discard(static_cast<size_t>(count) + 1);
  exclusive_scan(backend, stream, flags.data(), count + 1, ranks->data());
  return static_cast<int64_t>(ranks->element(count, stream));
}

template <class Backend>
void fill_empty(Backend backend, const Stream& stream, Buffer<uint64_t>* keys) {
  (void)backend;
  keys->fill_bytes(0xff, stream);  // every byte 0xff == kEmptyBlockKey
}

inline uint64_t buckets_for(int64_t live_keys, double max_load_factor) {
  return static_cast<uint64_t>(std::ceil(static_cast<double>(live_keys) / max_load_factor)) + 1;
}

}  // namespace internal

template <class Backend>
void hash_table_rehash(Backend backend, BlockHashTableState& state, uint64_t new_bucket_count,
                       const Stream& stream) {
  if (new_bucket_count < static_cast<uint64_t>(state.live_count) + 1) {
    throw Error("BlockHashTable::rehash: " + std::to_string(new_bucket_count) +
                " buckets cannot hold " + std::to_string(state.live_count) + " keys");
  }
  Buffer<uint64_t> new_keys(state.device, new_bucket_count);
  Buffer<uint32_t> new_slots(state.device, new_bucket_count);
  internal::fill_empty(backend, stream, &new_keys);
  const BlockHashTableView from = state.view();
  const BlockHashTableView to{new_keys.data(), new_slots.data(), new_bucket_count};
  parallel_for(backend, stream, static_cast<int64_t>(from.bucket_count), [=] COVOX_HD(int64_t b) {
    const uint64_t key = from.keys[b];
    if (!is_live_block_key(key)) return;
    bool inserted = false;
    const uint64_t bucket = to.insert(key, &inserted);
    to.slots[bucket] = from.slots[b];  // live keys are unique, so insert() always succeeds here
  });
  stream.synchronize();
  state.keys = std::move(new_keys);
  state.slots = std::move(new_slots);
  state.occupied_count = state.live_count;
  ++state.rehash_count;
}

// Counts the distinct keys of a batch that are not in the table yet (the exact growth need).
template <class Backend>
int64_t hash_table_count_distinct_missing(Backend backend, BlockHashTableState& state,
                                          const Index3D* keys, int64_t count,
                                          const Stream& stream) {
  state.scratch_keys.resize_discard(static_cast<size_t>(count));
  uint64_t* missing = state.scratch_keys.data();
  const BlockHashTableView table = state.view();
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    const uint64_t key = pack_block_key(keys[i]);
    missing[i] = (key != kInvalidBlockKey && table.find(key) == kNoBucket) ? key : kEmptyBlockKey;
  });
  sort(backend, stream, missing, count);
  const int64_t distinct = unique(backend, stream, missing, count);
  if (distinct == 0) return 0;
  const bool has_sentinel = state.scratch_keys.element(distinct - 1, stream) == kEmptyBlockKey;
  return distinct - (has_sentinel ? 1 : 0);
}

// Grows (or just cleans tombstones out of) the table so that the batch fits below the maximum
// load factor. The cheap bound (every key new) is tried first; only when it fails is the exact
// number of distinct new keys computed, so pre-sized tables pay nothing.
template <class Backend>
void hash_table_grow_for_batch(Backend backend, BlockHashTableState& state, const Index3D* keys,
                               int64_t count, const Stream& stream) {
  const double limit = state.config.max_load_factor * static_cast<double>(state.bucket_count());
  if (static_cast<double>(state.occupied_count + count) <= limit) return;
  const int64_t missing = hash_table_count_distinct_missing(backend, state, keys, count, stream);
  if (static_cast<double>(state.occupied_count + missing) <= limit) return;
  // Tombstones vanish in a rehash, so size for live + new keys only.
  uint64_t buckets = std::max<uint64_t>(state.bucket_count(), 16);
  const int64_t needed = state.live_count + missing;
  while (static_cast<double>(needed) > state.config.max_load_factor * 0.75 * buckets) buckets *= 2;
  hash_table_rehash(backend, state, buckets, stream);
}

namespace internal {

// Steps 1 to 3 for the first `count` keys, or, when `count_on_device` is given, for the first
// *count_on_device of them (`count` is then a bound; the keys past it get no bucket), in one
// launch: each key is inserted by the scan that ranks the new ones (exclusive_scan_of reads each
// value once), and as each new key's rank is known it gets its slot; ranks[count] is the number
// of new keys. Keys that could not be placed (outside the key range, table full) are counted in
// the state's failure counter, which the gather reads and clears. One launch instead of a memset,
// an insert kernel, a scan and an assignment kernel: a TSDF frame waits for each launch's host
// cost.
template <class Backend>
void activate_insert_rank_and_assign(Backend backend, BlockHashTableState& state,
                                     const Index3D* keys, int64_t count,
                                     const uint32_t* count_on_device, const Stream& stream) {
  state.scratch_buckets.resize_discard(static_cast<size_t>(count));
  state.scratch_flags.resize_discard(static_cast<size_t>(count));
  state.scratch_ranks.resize_discard(static_cast<size_t>(count) + 1);
  uint64_t* buckets = state.scratch_buckets.data();
  uint32_t* new_flags = state.scratch_flags.data();
  uint32_t* ranks = state.scratch_ranks.data();
  uint32_t* failures = state.activation_failures(stream);
  const BlockHashTableView table = state.view();
  const uint32_t* free_stack = state.free_slots.data();
  const uint32_t free_count = state.free_count;
  const uint32_t next_unused = state.next_unused_slot;
  // one key per GPU thread: an insertion is a chain of dependent probes
  exclusive_scan_of<1>(
      backend, stream, count + 1,
      [=] COVOX_HD(int64_t i) -> uint32_t {
        if (i == count) return 0u;
        if (count_on_device && i >= *count_on_device) {
          buckets[i] = kNoBucket;
          new_flags[i] = 0u;
          return 0u;
        }
        const uint64_t key = pack_block_key(keys[i]);
        bool inserted = false;
        const uint64_t bucket = key == kInvalidBlockKey ? kNoBucket : table.insert(key, &inserted);
        buckets[i] = bucket;
        new_flags[i] = inserted ? 1u : 0u;
        if (bucket >= kTableFullBucket) atomic_add(failures, 1u);
        return inserted ? 1u : 0u;
      },
      [=] COVOX_HD(int64_t i, uint32_t rank) {
        ranks[i] = rank;
        // (the scan called value_of(i) before, in this block)
        if (i < count && new_flags[i])
          table.slots[buckets[i]] = new_key_slot(free_stack, free_count, next_unused, rank);
      },
      ranks);  // (the CPU twin's scratch: the prefixes land where the output puts them anyway)
}

// Step 4. The gather reads every key's slot, so it runs without the host knowing whether any
// key is new (and after every assignment, for a batch that holds a new key more than once).
// `totals_out` (device memory) gets the new keys' and the failures' totals from the gather's
// first thread, which also clears the failure counter for the next call.
template <class Backend>
void activate_gather(Backend backend, BlockHashTableState& state, int64_t count,
                     uint32_t* slots_out, uint8_t* is_new_out, uint32_t* totals_out,
                     const Stream& stream) {
  const uint64_t* buckets = state.scratch_buckets.data();
  const uint32_t* new_flags = state.scratch_flags.data();
  const uint32_t* ranks = state.scratch_ranks.data();
  uint32_t* failures = state.activation_failures(stream);
  const BlockHashTableView table = state.view();
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    if (i == 0) {
      totals_out[0] = ranks[count];
      totals_out[1] = *failures;
      *failures = 0u;
    }
    const uint64_t bucket = buckets[i];
    slots_out[i] = bucket < table.bucket_count ? table.slots[bucket] : kInvalidSlot;
    if (is_new_out) is_new_out[i] = static_cast<uint8_t>(new_flags[i]);
  });
}

// The host's part once the totals are known (activate_finish_counted, block_hash_table.cpp: slot
// bookkeeping and warnings), with the failures' kinds found from the batch's buckets.
template <class Backend>
ActivateResult activate_finish(Backend backend, BlockHashTableState& state, int64_t count,
                               int64_t num_new, int64_t failed, const Stream& stream) {
  // Failures are rare: their kinds are counted only when there were any.
  const int64_t full =
      failed > 0 ? count_if(backend, stream, state.scratch_buckets.data(), count,
                            [] COVOX_HD(uint64_t bucket) { return bucket == kTableFullBucket; })
                 : 0;
  return activate_finish_counted(state, num_new, failed - full, full);
}

}  // namespace internal

template <class Backend>
ActivateResult hash_table_activate(Backend backend, BlockHashTableState& state, const Index3D* keys,
                                   int64_t count, uint32_t* slots_out, uint8_t* is_new_out,
                                   const Stream& stream) {
  if (count <= 0) return ActivateResult{};
  if (state.config.allow_growth) hash_table_grow_for_batch(backend, state, keys, count, stream);
  internal::activate_insert_rank_and_assign(backend, state, keys, count, nullptr, stream);
  uint32_t* totals_on_device = state.activation_failures(stream) + 1;
  internal::activate_gather(backend, state, count, slots_out, is_new_out, totals_on_device, stream);
  uint32_t totals[2];
  copy_bytes(totals, Device::kCpu, totals_on_device, state.activation_words.device(),
             sizeof(totals), stream);
  return internal::activate_finish(backend, state, count, totals[0], totals[1], stream);
}

template <class Backend>
bool hash_table_activate_queued(Backend backend, BlockHashTableState& state, const Index3D* keys,
                                const uint32_t* count_on_device, int64_t count_bound,
                                uint32_t* slots_out, uint8_t* is_new_out, uint32_t* totals_out,
                                const Stream& stream) {
  if (state.pending_count >= 0)
    throw Error("BlockHashTable::activate_queued: the previous one is not finished");
  // Growth needs the exact count of new keys: the caller takes the synchronous path then.
  if (count_bound <= 0 || state.might_grow_for(count_bound)) return false;
  internal::activate_insert_rank_and_assign(backend, state, keys, count_bound, count_on_device,
                                            stream);
  internal::activate_gather(backend, state, count_bound, slots_out, is_new_out, totals_out, stream);
  state.pending_count = count_bound;
  return true;
}

template <class Backend>
ActivateResult hash_table_finish_queued(Backend backend, BlockHashTableState& state,
                                        uint32_t num_new, uint32_t failed, const Stream& stream) {
  if (state.pending_count < 0)
    throw Error("BlockHashTable::finish_queued_activation: no activation is queued");
  const int64_t count = state.pending_count;
  state.pending_count = -1;
  return internal::activate_finish(backend, state, count, num_new, failed, stream);
}

template <class Backend>
int64_t hash_table_find(Backend backend, BlockHashTableState& state, const Index3D* keys,
                        int64_t count, uint32_t* slots_out, const Stream& stream) {
  if (count <= 0) return 0;
  const BlockHashTableView table = state.view();
  parallel_for(backend, stream, count,
               [=] COVOX_HD(int64_t i) { slots_out[i] = table.slot_of(keys[i]); });
  return count_if(backend, stream, slots_out, count,
                  [] COVOX_HD(uint32_t slot) { return slot != kInvalidSlot; });
}

template <class Backend>
int64_t hash_table_erase(Backend backend, BlockHashTableState& state, const Index3D* keys,
                         int64_t count, const Stream& stream) {
  if (count <= 0) return 0;
  state.scratch_flags.resize_discard(static_cast<size_t>(count) + 1);
  state.scratch_slots.resize_discard(static_cast<size_t>(count));
  uint32_t* erased_flags = state.scratch_flags.data();
  uint32_t* erased_slots = state.scratch_slots.data();
  const BlockHashTableView table = state.view();
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    erased_flags[i] = 0;
    const uint64_t key = pack_block_key(keys[i]);
    if (key == kInvalidBlockKey) return;
    const uint64_t bucket = table.find(key);
    if (bucket == kNoBucket) return;
    // Only one of several duplicates wins the CAS and releases the slot.
    if (atomic_compare_exchange(&table.keys[bucket], key, kErasedBlockKey) == key) {
      erased_flags[i] = 1;
      erased_slots[i] = table.slots[bucket];
      table.slots[bucket] = kInvalidSlot;
    }
  });
  const int64_t num_erased =
      internal::rank_flags(backend, stream, state.scratch_flags, &state.scratch_ranks, count);
  if (num_erased == 0) return 0;
  const size_t needed = static_cast<size_t>(state.free_count) + static_cast<size_t>(num_erased);
  if (state.free_slots.size() < needed) {
    state.free_slots.resize(std::max<size_t>(needed, state.next_unused_slot), stream);
  }
  uint32_t* free_stack = state.free_slots.data();
  const uint32_t* ranks = state.scratch_ranks.data();
  const uint32_t free_count = state.free_count;
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    if (erased_flags[i]) free_stack[free_count + ranks[i]] = erased_slots[i];
  });
  state.free_count += static_cast<uint32_t>(num_erased);
  state.live_count -= num_erased;
  return num_erased;
}

template <class Backend>
void hash_table_export(Backend backend, BlockHashTableState& state, Buffer<Index3D>* keys_out,
                       Buffer<uint32_t>* slots_out, const Stream& stream) {
  const int64_t buckets = static_cast<int64_t>(state.bucket_count());
  keys_out->resize_discard(static_cast<size_t>(state.live_count));
  slots_out->resize_discard(static_cast<size_t>(state.live_count));
  if (state.live_count == 0) return;
  state.scratch_flags.resize_discard(static_cast<size_t>(buckets) + 1);
  uint32_t* live_flags = state.scratch_flags.data();
  const BlockHashTableView table = state.view();
  parallel_for(backend, stream, buckets, [=] COVOX_HD(int64_t b) {
    live_flags[b] = is_live_block_key(table.keys[b]) ? 1u : 0u;
  });
  internal::rank_flags(backend, stream, state.scratch_flags, &state.scratch_ranks, buckets);
  const uint32_t* ranks = state.scratch_ranks.data();
  Index3D* out_keys = keys_out->data();
  uint32_t* out_slots = slots_out->data();
  parallel_for(backend, stream, buckets, [=] COVOX_HD(int64_t b) {
    if (!live_flags[b]) return;
    out_keys[ranks[b]] = unpack_block_key(table.keys[b]);
    out_slots[ranks[b]] = table.slots[b];
  });
  stream.synchronize();
}

// Explicit instantiation list, used by the two backend files.
#define COVOX_INSTANTIATE_BLOCK_HASH_TABLE(Backend)                                                \
  template void hash_table_rehash<Backend>(Backend, BlockHashTableState&, uint64_t,                \
                                           const Stream&);                                         \
  template ActivateResult hash_table_activate<Backend>(                                            \
      Backend, BlockHashTableState&, const Index3D*, int64_t, uint32_t*, uint8_t*, const Stream&); \
  template bool hash_table_activate_queued<Backend>(Backend, BlockHashTableState&, const Index3D*, \
                                                    const uint32_t*, int64_t, uint32_t*, uint8_t*, \
                                                    uint32_t*, const Stream&);                     \
  template ActivateResult hash_table_finish_queued<Backend>(Backend, BlockHashTableState&,         \
                                                            uint32_t, uint32_t, const Stream&);    \
  template int64_t hash_table_find<Backend>(Backend, BlockHashTableState&, const Index3D*,         \
                                            int64_t, uint32_t*, const Stream&);                    \
  template int64_t hash_table_erase<Backend>(Backend, BlockHashTableState&, const Index3D*,        \
                                             int64_t, const Stream&);                              \
  template void hash_table_export<Backend>(Backend, BlockHashTableState&, Buffer<Index3D>*,        \
                                           Buffer<uint32_t>*, const Stream&);

}  // namespace covox::map

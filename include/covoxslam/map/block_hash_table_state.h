#pragma once
// The data of a BlockHashTable, shared by its CPU and CUDA implementations
// (block_hash_table_impl.h). Not for direct use: go through BlockHashTable.
#include <cstdint>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/map/block_hash_table_view.h"

namespace covox::map {

struct BlockHashTableConfig {
  // Buckets allocated up front. Size it for the expected number of blocks / max_load_factor to
  // avoid rehashing while mapping (a rehash costs one pass over the table).
  uint64_t initial_bucket_count = 1 << 16;
  // Growth happens before (live keys + tombstones) / buckets would pass this. Linear probing
  // stays fast up to about 0.85; the table stays correct above it when growth is disabled.
  double max_load_factor = 0.75;
  // When false the table never rehashes on its own: keys that find no free bucket fail, are
  // counted, and a warning says the table is full.
  bool allow_growth = true;
};

// What one activate() call did.
struct ActivateResult {
  int64_t num_new = 0;           // keys this call inserted (each counted once)
  int64_t num_out_of_range = 0;  // rejected: a component outside [kMinBlockIndex, kMaxBlockIndex]
  int64_t num_failed_full = 0;   // rejected: no free bucket (growth disabled or impossible)
  bool ok() const { return num_out_of_range == 0 && num_failed_full == 0; }
};

struct BlockHashTableState {
  explicit BlockHashTableState(Device device_in = Device::kCpu)
      : device(device_in),
        keys(device_in),
        slots(device_in),
        free_slots(device_in),
        scratch_buckets(device_in),
        scratch_flags(device_in),
        scratch_ranks(device_in),
        scratch_slots(device_in),
        scratch_keys(device_in),
        activation_words(device_in) {}

  Device device;
  BlockHashTableConfig config;

  Buffer<uint64_t> keys;        // bucket -> packed key (or empty / erased)
  Buffer<uint32_t> slots;       // bucket -> slot
  Buffer<uint32_t> free_slots;  // stack of slots released by erase(); top is the end
  uint32_t free_count = 0;
  uint32_t next_unused_slot = 0;

  int64_t live_count = 0;      // keys present
  int64_t occupied_count = 0;  // keys present + tombstones
  int64_t total_out_of_range = 0;
  int64_t total_failed_full = 0;
  int64_t rehash_count = 0;
  int64_t pending_count = -1;      // a queued activation's key bound until it is finished; -1: none
  bool pending_in_kernel = false;  // the pending activation is an in-kernel one (block_activator.h)

  // Per-batch scratch, kept between calls so steady-state batches allocate nothing.
  Buffer<uint64_t> scratch_buckets;
  Buffer<uint32_t> scratch_flags;
  Buffer<uint32_t> scratch_ranks;
  Buffer<uint32_t> scratch_slots;
  Buffer<uint64_t> scratch_keys;
  // activate(): the failure counter (zero between calls: zeroed once, cleared by each call's
  // gather) and, after it, the totals of the synchronous activate(). Returns the counter.
  // [0] the batch activation's failures, [1..2] its totals; [3..5] the in-kernel activation's
  // counters (BlockActivator). Zero between activations.
  Buffer<uint32_t> activation_words;
  uint32_t* activation_failures(const Stream& stream) {
    if (activation_words.size() < 6) {
      activation_words.resize_discard(6);
      activation_words.fill_bytes(0, stream);
    }
    return activation_words.data();
  }

  uint64_t bucket_count() const { return keys.size(); }
  // Whether `new_keys` more keys could take the table past its maximum load factor (it would
  // grow): an activation that cannot count its new keys first must then take the synchronous path.
  bool might_grow_for(int64_t new_keys) const {
    return config.allow_growth && static_cast<double>(occupied_count + new_keys) >
                                      config.max_load_factor * static_cast<double>(bucket_count());
  }
  BlockHashTableView view() { return BlockHashTableView{keys.data(), slots.data(), keys.size()}; }
};

}  // namespace covox::map

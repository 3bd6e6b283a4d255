#pragma once
// Insert-if-absent of distinct block keys one at a time, from inside the caller's own kernel
// (BlockHashTable::begin_in_kernel_activation), for a caller that lists its keys in a kernel
// anyway: a TSDF frame activates each block in the scan of its walk's marks as its rank is known
// (stage 4a, internal/tsdf_stage_blocks.h), saving a launch and a pass over the keys. Each new key
// takes the next slot by an atomic counter (freed slots first, then never-used ones): the slots
// activate() would hand out, in an order set by thread timing. Keys must be distinct within one
// activation (a second occurrence of a new key could read its slot before it is written). One
// thread of a later kernel hands the totals over and clears the counters (hand_over_totals); the
// host passes them to BlockHashTable::finish_in_kernel_activation().
#include <cstdint>

#include "covoxslam/core/atomics.h"
#include "covoxslam/core/index3d.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/map/block_hash_table_view.h"
#include "covoxslam/map/block_key.h"

namespace covox::map {

struct BlockActivator {
  BlockHashTableView table;
  const uint32_t* free_stack = nullptr;
  uint32_t free_count = 0;
  uint32_t next_unused = 0;
  // Device words, zero before the activation: [0] new keys, [1] keys outside the key range,
  // [2] keys that found the table full.
  uint32_t* counters = nullptr;

  // The slot of `block` (kInvalidSlot when rejected); *is_new tells whether this call created it.
  COVOX_HD_INLINE uint32_t activate(const Index3D& block, bool* is_new) const {
    *is_new = false;
    const uint64_t key = pack_block_key(block);
    if (key == kInvalidBlockKey) {
      atomic_add(&counters[1], 1u);
      return kInvalidSlot;
    }
    bool inserted = false;
    const uint64_t bucket = table.insert(key, &inserted);
    if (bucket >= kTableFullBucket) {
      atomic_add(&counters[2], 1u);
      return kInvalidSlot;
    }
    if (!inserted) return table.slots[bucket];
    const uint32_t slot =
        new_key_slot(free_stack, free_count, next_unused, atomic_add(&counters[0], 1u));
    table.slots[bucket] = slot;
    *is_new = true;
    return slot;
  }

  // Called by one thread of a kernel after the activating one: the totals (new keys, keys outside
  // the range, keys that found the table full) into out[0..2], the counters cleared for the next.
  COVOX_HD_INLINE void hand_over_totals(uint32_t* out) const {
    for (int k = 0; k < 3; ++k) {
      out[k] = counters[k];
      counters[k] = 0u;
    }
  }
};

}  // namespace covox::map

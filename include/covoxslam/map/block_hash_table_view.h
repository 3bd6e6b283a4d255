#pragma once
// The device-side view of a BlockHashTable: plain pointers, copied by value into kernels.
// Open addressing with linear probing over `bucket_count` buckets; keys and slots are two
// separate arrays (SoA), so a probe sequence touches only the 8-byte keys.
//
// Concurrency contract (what makes lock-free insertion correct):
//  * during one insert batch a bucket only changes EMPTY -> key (by CAS), so a thread that reads
//    a stale EMPTY simply loses the CAS and learns the real key from its return value;
//  * erase (key -> ERASED) runs in its own batch, never concurrently with inserts;
//  * insertion never reuses ERASED buckets (two threads could otherwise claim two different
//    tombstones for the same key); tombstones are reclaimed by rehash().
#include <cstdint>

#include "covoxslam/core/atomics.h"
#include "covoxslam/map/block_key.h"

namespace covox::map {

constexpr uint64_t kNoBucket = ~uint64_t(0);             // key not present / out of range
constexpr uint64_t kTableFullBucket = ~uint64_t(0) - 1;  // probed every bucket, none free

// The slot of an activation's k-th new key: freed slots first (from the top of the free stack),
// then never-used ones. The same rule for the batch activation (its rank scan) and the in-kernel
// one (its counter, block_activator.h).
COVOX_HD_INLINE uint32_t new_key_slot(const uint32_t* free_stack, uint32_t free_count,
                                      uint32_t next_unused, uint32_t k) {
  return k < free_count ? free_stack[free_count - 1 - k] : next_unused + (k - free_count);
}

struct BlockHashTableView {
  uint64_t* keys = nullptr;
  uint32_t* slots = nullptr;
  uint64_t bucket_count = 0;

  COVOX_HD_INLINE uint64_t next(uint64_t bucket) const {
    return bucket + 1 == bucket_count ? 0 : bucket + 1;
  }

  // Inserts `key` if absent. Returns its bucket, or kTableFullBucket. `inserted` is true only for
  // the one thread whose CAS placed the key.
  COVOX_HD_INLINE uint64_t insert(uint64_t key, bool* inserted) const {
    *inserted = false;
    uint64_t bucket = home_bucket(mix_block_key(key), bucket_count);
    for (uint64_t probe = 0; probe < bucket_count; ++probe) {
      uint64_t current = atomic_load_relaxed(&keys[bucket]);
      if (current == kEmptyBlockKey) {
        current = atomic_compare_exchange(&keys[bucket], kEmptyBlockKey, key);
        if (current == kEmptyBlockKey) {
          *inserted = true;
          return bucket;
        }
      }
      if (current == key) return bucket;
      bucket = next(bucket);
    }
    return kTableFullBucket;
  }

  // The slot of the block with index `block`, or kInvalidSlot when it is not allocated (or lies
  // outside the key range).
  COVOX_HD_INLINE uint32_t slot_of(const Index3D& block) const {
    const uint64_t key = pack_block_key(block);
    if (key == kInvalidBlockKey) return kInvalidSlot;
    const uint64_t bucket = find(key);
    return bucket == kNoBucket ? kInvalidSlot : slots[bucket];
  }

  // Returns the bucket holding `key`, or kNoBucket.
  COVOX_HD_INLINE uint64_t find(uint64_t key) const {
    uint64_t bucket = home_bucket(mix_block_key(key), bucket_count);
    for (uint64_t probe = 0; probe < bucket_count; ++probe) {
      const uint64_t current = atomic_load_relaxed(&keys[bucket]);
      if (current == key) return bucket;
      if (current == kEmptyBlockKey) return kNoBucket;
      bucket = next(bucket);
    }
    return kNoBucket;
  }
};

}  // namespace covox::map

#pragma once
// A set of block keys on the host, for membership tests in tight loops (the overlap tests of
// submap footprints against every earlier submap). Open addressing with linear probing in one
// flat array kept at most half full: a lookup is one hash and a scan of adjacent words, with no
// bucket division or node to follow as in std::unordered_set.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "covoxslam/map/block_key.h"

namespace covox::map {

class BlockKeySet {
 public:
  BlockKeySet() = default;
  // The live keys among `keys` (is_live_block_key), each stored once; the others are left out.
  explicit BlockKeySet(const std::vector<uint64_t>& keys) {
    buckets_.assign(std::max<size_t>(2 * keys.size(), 8), kEmptyBlockKey);
    for (const uint64_t key : keys) {
      if (!is_live_block_key(key)) continue;
      size_t b = home_bucket(mix_block_key(key), buckets_.size());
      while (buckets_[b] != kEmptyBlockKey && buckets_[b] != key) b = next(b);
      if (buckets_[b] == kEmptyBlockKey) ++size_;
      buckets_[b] = key;
    }
  }

  bool contains(uint64_t key) const {
    if (buckets_.empty() || !is_live_block_key(key)) return false;
    // Terminates: at least half of the buckets are empty.
    for (size_t b = home_bucket(mix_block_key(key), buckets_.size());; b = next(b)) {
      if (buckets_[b] == key) return true;
      if (buckets_[b] == kEmptyBlockKey) return false;
    }
  }

  size_t size() const { return size_; }

 private:
  size_t next(size_t bucket) const { return bucket + 1 == buckets_.size() ? 0 : bucket + 1; }

  std::vector<uint64_t> buckets_;  // kEmptyBlockKey where unused
  size_t size_ = 0;
};

}  // namespace covox::map

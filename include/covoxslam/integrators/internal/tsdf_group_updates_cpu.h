#pragma once
// Stage 3 of a TSDF frame on the CPU twin: group the visit records by voxel and sum each voxel's,
// with the same result as the GPU's stable radix sort by key plus reduction by key (merged keys
// ascending, each voxel's records summed left to right in record order), with less memory
// traffic.
//
// A radix sort of 22-bit keys moves every record three times; here each record moves once: a
// stable counting sort by block (the key's block part, a few thousand values), then each block's
// records are summed into a dense array of the block's voxels (L1-resident), read out in voxel
// order. Records to drop (zero weight, outside the box) are counted, not summed, as the GPU
// path counts them.
#include <omp.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox::integrators::tsdf {

// More blocks than this in a frame's box (only boxes of 64-bit keys come near it) and the
// per-thread block histograms would cost more than the radix sort they replace.
constexpr int64_t kMaxDenseGroupingBlocks = int64_t(1) << 16;

inline bool dense_grouping_fits(const FrameKeyCodec& codec) {
  return static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z <=
         kMaxDenseGroupingBlocks;
}

// What the grouping found; the GPU path leaves the same figures in its read-back buffer.
struct GroupCounts {
  uint32_t runs = 0;          // distinct voxels plus one run per kind of dropped record present
  uint32_t zero_weight = 0;   // records that carried no weight
  uint32_t out_of_range = 0;  // records of voxels outside the frame's box
  uint32_t voxels = 0;        // distinct voxels written to merged_keys / merged
};

// 1. A stable counting sort of `count` records by block (the last bucket holds every record to
//    drop) into keys_alt / values_alt: thread t owns the t-th chunk of records, and a bucket's
//    records are placed chunk by chunk, so each bucket keeps the records' order. Returns where
//    each bucket begins (buckets + 1 entries).
template <class KeyT, class ValueT>
std::vector<int64_t> sort_records_by_block(const FrameKeyCodec& codec, const KeyT* keys,
                                           const ValueT* values, int64_t count, KeyT* keys_alt,
                                           ValueT* values_alt) {
  const int64_t blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  const int64_t buckets = blocks + 1;
  const int voxel_bits = codec.voxel_bits;
  const auto bucket_of = [&](KeyT key) {
    const int64_t block = static_cast<int64_t>(static_cast<uint64_t>(key) >> voxel_bits);
    return block < blocks ? block : blocks;
  };
  const int max_threads = omp_get_max_threads();
  std::vector<int64_t> offsets(static_cast<size_t>(max_threads) * buckets);
  std::vector<int64_t> bucket_begin(static_cast<size_t>(buckets) + 1);
#pragma omp parallel num_threads(max_threads)
  {
    const int threads = omp_get_num_threads();
    const int thread = omp_get_thread_num();
    const int64_t begin = count * thread / threads, end = count * (thread + 1) / threads;
    int64_t* histogram = offsets.data() + static_cast<size_t>(thread) * buckets;
    std::fill(histogram, histogram + buckets, 0);
    for (int64_t i = begin; i < end; ++i) ++histogram[bucket_of(keys[i])];
#pragma omp barrier
#pragma omp single
    {
      int64_t running = 0;
      for (int64_t b = 0; b < buckets; ++b) {
        bucket_begin[static_cast<size_t>(b)] = running;
        for (int t = 0; t < threads; ++t) {
          int64_t& slot = offsets[static_cast<size_t>(t) * buckets + b];
          const int64_t n = slot;
          slot = running;
          running += n;
        }
      }
      bucket_begin[static_cast<size_t>(buckets)] = running;
    }
    for (int64_t i = begin; i < end; ++i) {
      const int64_t position = histogram[bucket_of(keys[i])]++;
      keys_alt[position] = keys[i];
      values_alt[position] = values[i];
    }
  }
  return bucket_begin;
}

// 2. The distinct voxels per block (a bitmap of the block's voxels), scanned into where each
//    block's sums go (blocks + 1 entries: the last is the total).
template <class KeyT>
std::vector<int64_t> first_voxel_of_blocks(const FrameKeyCodec& codec, const KeyT* keys_alt,
                                           const std::vector<int64_t>& bucket_begin) {
  const int64_t blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  const int voxels_per_block = 1 << codec.voxel_bits;
  const int words = (voxels_per_block + 63) / 64;
  const uint64_t local_mask = (uint64_t(1) << codec.voxel_bits) - 1;
  std::vector<int64_t> first_voxel(static_cast<size_t>(blocks) + 1, 0);
#pragma omp parallel num_threads(omp_get_max_threads())
  {
    std::vector<uint64_t> seen(static_cast<size_t>(words), 0);
#pragma omp for schedule(dynamic, 16)
    for (int64_t b = 0; b < blocks; ++b) {
      int64_t distinct = 0;
      for (int64_t j = bucket_begin[static_cast<size_t>(b)];
           j < bucket_begin[static_cast<size_t>(b) + 1]; ++j) {
        const uint64_t local = static_cast<uint64_t>(keys_alt[j]) & local_mask;
        const uint64_t bit = uint64_t(1) << (local & 63);
        uint64_t& word = seen[local >> 6];
        distinct += (word & bit) ? 0 : 1;
        word |= bit;
      }
      if (distinct > 0) std::fill(seen.begin(), seen.end(), 0);
      first_voxel[static_cast<size_t>(b) + 1] = distinct;
    }
  }
  for (int64_t b = 0; b < blocks; ++b)
    first_voxel[static_cast<size_t>(b) + 1] += first_voxel[static_cast<size_t>(b)];
  return first_voxel;
}

// 3. Each block's records summed in order into its voxels (update_of(j): moved record j's term,
//    combine(a, b): two terms added), read out in voxel (= key) order into merged_keys / merged.
template <class KeyT, class SumT, class UpdateOf, class Combine>
void sum_block_voxels(const FrameKeyCodec& codec, const KeyT* keys_alt,
                      const std::vector<int64_t>& bucket_begin,
                      const std::vector<int64_t>& first_voxel, KeyT* merged_keys, SumT* merged,
                      const UpdateOf& update_of, const Combine& combine) {
  const int64_t blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  const int voxel_bits = codec.voxel_bits;
  const int voxels_per_block = 1 << voxel_bits;
  const int words = (voxels_per_block + 63) / 64;
  const uint64_t local_mask = (uint64_t(1) << voxel_bits) - 1;
#pragma omp parallel num_threads(omp_get_max_threads())
  {
    std::vector<uint64_t> seen(static_cast<size_t>(words), 0);
    std::vector<SumT> sums(static_cast<size_t>(voxels_per_block));
#pragma omp for schedule(dynamic, 16)
    for (int64_t b = 0; b < blocks; ++b) {
      const int64_t begin = bucket_begin[static_cast<size_t>(b)],
                    end = bucket_begin[static_cast<size_t>(b) + 1];
      if (begin == end) continue;
      for (int64_t j = begin; j < end; ++j) {
        const uint64_t local = static_cast<uint64_t>(keys_alt[j]) & local_mask;
        const uint64_t bit = uint64_t(1) << (local & 63);
        uint64_t& word = seen[local >> 6];
        const SumT term = update_of(j);
        sums[local] = (word & bit) ? combine(sums[local], term) : term;
        word |= bit;
      }
      int64_t out = first_voxel[static_cast<size_t>(b)];
      const KeyT block_key = static_cast<KeyT>(static_cast<uint64_t>(b) << voxel_bits);
      for (int w = 0; w < words; ++w) {
        for (uint64_t rest = seen[static_cast<size_t>(w)]; rest != 0; rest &= rest - 1) {
          const int local = w * 64 + __builtin_ctzll(rest);
          merged_keys[out] = block_key | static_cast<KeyT>(local);
          merged[out] = sums[static_cast<size_t>(local)];
          ++out;
        }
        seen[static_cast<size_t>(w)] = 0;
      }
    }
  }
}

// Groups `count` records (keys, values) by voxel. The records are first moved, stably and by
// block, to keys_alt / values_alt; update_of(j) then gives the sum term of moved record j (built
// by the caller over keys_alt / values_alt), and combine(a, b) adds two. Writes the distinct
// voxels' keys ascending to merged_keys and their sums to merged.
template <class KeyT, class ValueT, class SumT, class UpdateOf, class Combine>
GroupCounts group_updates_by_voxel_cpu(const FrameKeyCodec& codec, const KeyT* keys,
                                       const ValueT* values, int64_t count, KeyT* keys_alt,
                                       ValueT* values_alt, KeyT* merged_keys, SumT* merged,
                                       const UpdateOf& update_of, const Combine& combine) {
  const int64_t blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  const std::vector<int64_t> bucket_begin =
      sort_records_by_block(codec, keys, values, count, keys_alt, values_alt);
  const std::vector<int64_t> first_voxel = first_voxel_of_blocks(codec, keys_alt, bucket_begin);
  sum_block_voxels(codec, keys_alt, bucket_begin, first_voxel, merged_keys, merged, update_of,
                   combine);
  GroupCounts counts;
  counts.voxels = static_cast<uint32_t>(first_voxel[static_cast<size_t>(blocks)]);
  const KeyT zero_weight_key = static_cast<KeyT>(codec.zero_weight_key);
  for (int64_t j = bucket_begin[static_cast<size_t>(blocks)]; j < count; ++j) {
    if (keys_alt[j] == zero_weight_key) {
      ++counts.zero_weight;
    } else {
      ++counts.out_of_range;
    }
  }
  counts.runs =
      counts.voxels + (counts.zero_weight > 0 ? 1u : 0u) + (counts.out_of_range > 0 ? 1u : 0u);
  return counts;
}

}  // namespace covox::integrators::tsdf

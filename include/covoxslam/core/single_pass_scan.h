#pragma once
// The GPU version of exclusive_scan_of (include parallel.h for both backends; the CPU's writes
// the values to `out` and scans them in place with Thrust): exclusive prefix sums of 32-bit
// values given by a functor, in one kernel launch. A frame's small scans are bound by their
// launches, and CUB's DeviceScan costs a sizing call, an init kernel and a scan kernel (and a
// scan of stored values the kernel that writes them). This is a decoupled look-back scan
// (Merrill and Garland, 2016) whose tile descriptors carry an epoch: a descriptor left by an
// earlier scan on the same stream reads as "not yet published", so they need no init kernel.
#include <cstdint>

#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/stream.h"

#if defined(__CUDACC__)
#include <cub/block/block_scan.cuh>
#include "covoxslam/core/internal/cuda_check.cuh"
#endif

namespace covox {

// Consecutive values per GPU thread: 8 for values read from arrays (2048 per tile). A functor
// whose values cost a chain of dependent loads each (a binary search) runs faster with fewer
// per thread and more tiles: exclusive_scan_of<1>(...).
constexpr int kScanItemsPerThread = 8;

// Where exclusive_scan_of puts prefix i: an array, or a functor's call.
COVOX_HD_INLINE void scan_output(uint32_t* out, int64_t i, uint32_t prefix) { out[i] = prefix; }
template <class Output>
COVOX_HD_INLINE void scan_output(const Output& out, int64_t i, uint32_t prefix) {
  out(i, prefix);
}

#if defined(__CUDACC__)
namespace internal {

constexpr int kThreads = 256;

// A descriptor word: kind (2 bits), epoch (30 bits), value (32 bits), published by one 64-bit
// store so that the value and its kind arrive together.
constexpr uint64_t kTileSum = uint64_t(1) << 62;     // the tile's own sum
constexpr uint64_t kTilePrefix = uint64_t(2) << 62;  // the sum of the tile and all before it
constexpr uint32_t kEpochMask = (1u << 30) - 1u;

// The values of an array (exclusive_scan of uint32_t).
struct ArrayValues {
  const uint32_t* in;
  __device__ __forceinline__ uint32_t operator()(int64_t i) const { return in[i]; }
};

__device__ __forceinline__ uint64_t describe(uint64_t kind, uint32_t epoch, uint32_t value) {
  return kind | (static_cast<uint64_t>(epoch & kEpochMask) << 32) | value;
}
__device__ __forceinline__ void publish(uint64_t* word, uint64_t value) {
  *reinterpret_cast<volatile uint64_t*>(word) = value;
}
// Waits until `word` holds a descriptor of this scan (its epoch) and returns it.
__device__ __forceinline__ uint64_t await(const uint64_t* word, uint32_t epoch) {
  uint64_t seen;
  do {
    seen = *reinterpret_cast<const volatile uint64_t*>(word);
  } while (static_cast<uint32_t>(seen >> 32 & kEpochMask) != (epoch & kEpochMask) ||
           (seen >> 62) == 0u);
  return seen;
}

// The sum of the values of all tiles before `tile` (a decoupled look-back), for a kernel whose
// thread blocks are the tiles, in index order: called by the block's first warp (all 32 lanes),
// with the tile's own sum; returns the prefix in every lane and publishes the tile's sum and then
// its inclusive prefix. Tile 0 needs no descriptors (null when there is one tile only). Its
// predecessors' sums are read nearest first, one warp looking back 32 tiles at a time, until one
// of them has published its inclusive prefix.
__device__ __forceinline__ uint32_t look_back_tile_prefix(uint64_t* descriptors, uint32_t epoch,
                                                          int64_t tile, uint32_t tile_sum) {
  const int lane = static_cast<int>(threadIdx.x & 31u);
  uint32_t prefix = 0;
  if (tile == 0) {
    if (lane == 0 && descriptors) publish(&descriptors[0], describe(kTilePrefix, epoch, tile_sum));
    return 0;
  }
  if (lane == 0) publish(&descriptors[tile], describe(kTileSum, epoch, tile_sum));
  int64_t window_end = tile;  // looks at tiles window_end - 1 - lane
  while (true) {
    const int64_t predecessor = window_end - 1 - lane;
    const uint64_t seen = predecessor >= 0 ? await(&descriptors[predecessor], epoch) : kTilePrefix;
    const bool inclusive = (seen >> 62) == (kTilePrefix >> 62);
    const uint32_t stops = __ballot_sync(0xFFFFFFFFu, inclusive);
    const int nearest = stops ? __ffs(static_cast<int>(stops)) - 1 : 32;
    uint32_t value = lane <= nearest ? static_cast<uint32_t>(seen) : 0u;
#pragma unroll
    for (int offset = 16; offset > 0; offset >>= 1)
      value += __shfl_down_sync(0xFFFFFFFFu, value, offset);
    prefix += __shfl_sync(0xFFFFFFFFu, value, 0);
    if (stops) break;
    window_end -= 32;
  }
  if (lane == 0) publish(&descriptors[tile], describe(kTilePrefix, epoch, prefix + tile_sum));
  return prefix;
}

template <int kItems, class ValueOf, class Output>
__global__ void __launch_bounds__(kThreads)
    single_pass_scan_kernel(int64_t count, ValueOf value_of, Output out, uint64_t* descriptors,
                            uint32_t epoch) {
  constexpr int64_t kTile = int64_t(kThreads) * kItems;
  using BlockScan = cub::BlockScan<uint32_t, kThreads>;
  __shared__ typename BlockScan::TempStorage scan_storage;
  __shared__ uint32_t staged[kTile];  // the tile's values, then its outputs (coalesced in and out)
  __shared__ uint32_t tile_prefix;
  const int64_t tile = blockIdx.x;
  const int64_t tile_begin = tile * kTile;
  // 1. the values, in striped order (neighbouring threads, neighbouring i), then each thread's
  //    kItems consecutive ones and their sum
#pragma unroll
  for (int k = 0; k < kItems; ++k) {
    const int64_t i = tile_begin + k * kThreads + threadIdx.x;
    staged[k * kThreads + threadIdx.x] = i < count ? value_of(i) : 0u;
  }
  __syncthreads();
  uint32_t own[kItems];
  uint32_t thread_sum = 0;
#pragma unroll
  for (int k = 0; k < kItems; ++k) {
    own[k] = staged[threadIdx.x * kItems + k];
    thread_sum += own[k];
  }
  uint32_t thread_prefix = 0, tile_sum = 0;
  BlockScan(scan_storage).ExclusiveSum(thread_sum, thread_prefix, tile_sum);
  // 2. the tile's prefix: its predecessors' published sums (look_back_tile_prefix)
  if (threadIdx.x < 32) {
    const uint32_t prefix = look_back_tile_prefix(descriptors, epoch, tile, tile_sum);
    if (threadIdx.x == 0) tile_prefix = prefix;
  }
  __syncthreads();
  // 3. the outputs, staged back into shared memory and stored in striped order
  uint32_t running = tile_prefix + thread_prefix;
#pragma unroll
  for (int k = 0; k < kItems; ++k) {
    staged[threadIdx.x * kItems + k] = running;
    running += own[k];
  }
  __syncthreads();
#pragma unroll
  for (int k = 0; k < kItems; ++k) {
    const int64_t i = tile_begin + k * kThreads + threadIdx.x;
    if (i < count) scan_output(out, i, staged[k * kThreads + threadIdx.x]);
  }
}

}  // namespace internal

// out[i] = value_of(0) + ... + value_of(i - 1), sums modulo 2^32. value_of(i) is called exactly
// once for each i in [0, count) (so it may also write something of its own, such as the piece
// table beside the piece sizes), and `out` may be the array value_of reads, since each element is
// read before it is written. `out` may also be a functor, called as out(i, prefix) once for each
// i after value_of(i) (scan_output): what a kernel after the scan would have done with each
// prefix, without its launch. Tiles of 256 x kItems values, one thread block each: a block sums
// its tile, publishes the sum, finds its prefix from its predecessors' published sums (one warp
// looking back 32 tiles at a time) and publishes its inclusive prefix. Like CUB's scan it relies
// on blocks starting in index order (a block waits only for lower-numbered ones).
template <int kItems = kScanItemsPerThread, class ValueOf, class Output>
void exclusive_scan_of(CudaBackend, const Stream& stream, int64_t count, const ValueOf& value_of,
                       Output out) {
  using namespace internal;
  constexpr int64_t kTile = int64_t(kThreads) * kItems;
  if (count <= 0) return;
  const int64_t tiles = (count + kTile - 1) / kTile;
  if (tiles > 0x7FFFFFFF) throw Error("exclusive_scan_of: too many values for one launch");
  // One tile needs no descriptors (and no registry lookup).
  const ScanDescriptors descriptors =
      tiles > 1 ? single_pass_scan_descriptors(stream, tiles) : ScanDescriptors{};
  single_pass_scan_kernel<kItems><<<static_cast<unsigned>(tiles), kThreads, 0,
                                    static_cast<cudaStream_t>(stream.native_handle())>>>(
      count, value_of, out, descriptors.words, descriptors.epoch);
  cuda_check(cudaGetLastError(), "exclusive_scan_of kernel launch");
}
#endif

}  // namespace covox

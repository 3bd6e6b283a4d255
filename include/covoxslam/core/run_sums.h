#pragma once
// consume_run_sums: sums of the runs of equal keys in sorted records, handed straight to the
// caller's consumer (a TSDF frame's visit records sorted by voxel: one call per voxel with its
// merged update, which the consumer writes to the map), instead of a device-wide reduction by key
// that writes merged keys and sums for a second kernel to read back (CUB's, on wide coloured
// updates, also needs many registers per thread). The order of the additions is fixed by the
// records' positions, so the sums are the same every run (the two backends may round
// differently: the GPU adds a run's pieces as a tree).
#include <cstddef>
#include <cstdint>
#include <string>

#include "covoxslam/core/atomics.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/warp_reduce.h"

#if defined(__CUDACC__)
#include <cub/block/block_scan.cuh>
#include "covoxslam/core/internal/cuda_check.cuh"
#endif

namespace covox {

// Four records per thread and at most 80 registers, so that three blocks of 256 threads stay
// resident per SM: enough records per thread to hide the loads' latency, without the register
// count the compiler would pick on its own (which leaves too few threads resident).
constexpr int kRunSumThreads = 256;  // GPU threads per tile
constexpr int kRunSumItems = 4;      // consecutive records per GPU thread
constexpr int kRunSumBlocksPerSm = 3;
constexpr int64_t kRunSumTile = int64_t(kRunSumThreads) * kRunSumItems;

namespace internal {

constexpr uint32_t kNoRun = 0xFFFFFFFFu;

// A partial sum over consecutive records and the first record of the run it belongs to, kNoRun
// when that run started before the records summed.
template <class SumT>
struct RunPart {
  SumT sum;
  uint32_t first;
};

// Joins two partial sums of consecutive records, left then right: a run starting in the right
// one ends the left one's run (a segmented sum; associative, so a block scan may use it).
template <class Op>
struct JoinRunParts {
  Op op;
  template <class SumT>
  COVOX_HD_INLINE RunPart<SumT> operator()(const RunPart<SumT>& left,
                                           const RunPart<SumT>& right) const {
    return right.first != kNoRun ? right : RunPart<SumT>{op(left.sum, right.sum), left.first};
  }
};

// What each tile leaves for the runs that cross its edges.
template <class SumT>
struct TileParts {
  SumT* head_sums;        // the records before the tile's first run start (a run from earlier tiles
                          // ending or passing here); the whole tile when no run starts in it
  SumT* tail_sums;        // the partial sum of the tile's last run when it goes on past the tile
  uint32_t* tail_firsts;  // that run's first record; kNoRun when the last run ends in the tile or
                          // started before it
  uint8_t* passes;        // 1: no run starts in the tile and its last record's run goes on past it
};

// Carves the parts of `tiles` tiles out of one scratch buffer.
template <class SumT>
TileParts<SumT> carve_tile_parts(Buffer<uint64_t>& scratch, int64_t tiles) {
  const int64_t sum_words = (tiles * static_cast<int64_t>(sizeof(SumT)) + 7) / 8;
  const int64_t first_words = (tiles * 4 + 7) / 8;
  const int64_t pass_words = (tiles + 7) / 8;
  scratch.resize_discard(static_cast<size_t>(2 * sum_words + first_words + pass_words));
  uint64_t* words = scratch.data();
  return TileParts<SumT>{reinterpret_cast<SumT*>(words), reinterpret_cast<SumT*>(words + sum_words),
                         reinterpret_cast<uint32_t*>(words + 2 * sum_words),
                         reinterpret_cast<uint8_t*>(words + 2 * sum_words + first_words)};
}

// Record j's place after `part` (the partial sum up to j - 1): its run's partial sum with it
// added, handed over (to `hand_over`) or left in the tile's parts where the run ends or the tile
// does. The same step on both backends, after each has built `part` its own way.
template <class KeyT, class SumT, class HandOver>
COVOX_HD_INLINE void close_record(const KeyT* keys, int64_t count, int64_t j, int64_t tile,
                                  int64_t tile_end, const RunPart<SumT>& part,
                                  const HandOver& hand_over, const TileParts<SumT>& parts) {
  const bool ends = j + 1 >= count || keys[j + 1] != keys[j];
  if (ends) {
    if (part.first != kNoRun) {
      hand_over(static_cast<int64_t>(part.first), part.sum);
    } else {
      parts.head_sums[tile] = part.sum;  // the end of a run from earlier tiles
    }
  }
  if (j + 1 != tile_end) return;
  const bool goes_on = !ends;
  parts.tail_firsts[tile] = goes_on ? part.first : kNoRun;
  if (goes_on && part.first != kNoRun) parts.tail_sums[tile] = part.sum;
  if (goes_on && part.first == kNoRun) parts.head_sums[tile] = part.sum;
  parts.passes[tile] = goes_on && part.first == kNoRun ? 1u : 0u;
}

// The records there are: all `count_bound`, or the first *live_count (memory of the backend's
// device) when given.
COVOX_HD_INLINE int64_t live_records(int64_t count_bound, const uint32_t* live_count) {
  return live_count && static_cast<int64_t>(*live_count) < count_bound
             ? static_cast<int64_t>(*live_count)
             : count_bound;
}

template <class KeyT>
COVOX_HD_INLINE bool starts_run(const KeyT* keys, int64_t j) {
  return j == 0 || keys[j] != keys[j - 1];
}

// The CPU's tile: its records left to right.
template <class KeyT, class SumT, class Term, class Op, class Consume>
void sum_tile_in_order(const KeyT* keys, int64_t count, int64_t tile, const Term& term,
                       const Op& op, const Consume& consume, const TileParts<SumT>& parts,
                       uint32_t* run_count) {
  const int64_t begin = tile * kRunSumTile;
  const int64_t end = begin + kRunSumTile < count ? begin + kRunSumTile : count;
  RunPart<SumT> part{SumT{}, kNoRun};
  uint32_t starts = 0;
  for (int64_t j = begin; j < end; ++j) {
    const SumT value = term(j);
    const bool start = starts_run(keys, j);
    starts += start ? 1u : 0u;
    part = start ? RunPart<SumT>{value, static_cast<uint32_t>(j)}
                 : RunPart<SumT>{op(part.sum, value), part.first};
    close_record(keys, count, j, tile, end, part, consume, parts);
  }
  if (run_count && starts) atomic_add(run_count, starts);
}

#if defined(__CUDACC__)
template <class KeyT, class SumT, class Term, class Op, class Consume>
__global__ void __launch_bounds__(kRunSumThreads, kRunSumBlocksPerSm)
    sum_tiles_kernel(const KeyT* keys, int64_t count_bound, const uint32_t* live_count, Term term,
                     Op op, Consume consume, TileParts<SumT> parts, uint32_t* run_count) {
  const int64_t count = live_records(count_bound, live_count);
  if (static_cast<int64_t>(blockIdx.x) * kRunSumTile >= count)
    return;  // a tile past the live records
  using Part = RunPart<SumT>;
  using BlockScan = cub::BlockScan<Part, kRunSumThreads>;
  // The runs that end in the tile, handed to `consume` one per thread after the scan: a thread
  // consuming its own records' runs one after the other waited for each one's writes in turn
  // (consumers load and store: the voxel's slot, the voxel). The list takes the scan's place in
  // shared memory (48 KB at most).
  struct ClosedRuns {
    uint32_t firsts[kRunSumTile];
    SumT sums[kRunSumTile];
  };
  constexpr size_t kScanBytes = sizeof(typename BlockScan::TempStorage);
  constexpr size_t kSharedBytes = kScanBytes > sizeof(ClosedRuns) ? kScanBytes : sizeof(ClosedRuns);
  __shared__ alignas(16) unsigned char shared_bytes[kSharedBytes];
  __shared__ uint32_t closed_count;
  auto& scan_storage = *reinterpret_cast<typename BlockScan::TempStorage*>(shared_bytes);
  uint32_t* closed_firsts = reinterpret_cast<ClosedRuns*>(shared_bytes)->firsts;
  SumT* closed_sums = reinterpret_cast<ClosedRuns*>(shared_bytes)->sums;
  if (threadIdx.x == 0) closed_count = 0;
  const int64_t tile = blockIdx.x;
  const int64_t tile_begin = tile * kRunSumTile;
  const int64_t tile_end = tile_begin + kRunSumTile < count ? tile_begin + kRunSumTile : count;
  const int64_t first = tile_begin + static_cast<int64_t>(threadIdx.x) * kRunSumItems;
  // 1. this thread's records: their terms and run starts, and their partial sum
  SumT values[kRunSumItems];
  bool starts[kRunSumItems];
  Part own{SumT{}, kNoRun};
#pragma unroll
  for (int k = 0; k < kRunSumItems; ++k) {
    const int64_t j = first + k;
    starts[k] = false;
    if (j >= tile_end) continue;
    values[k] = term(j);
    starts[k] = starts_run(keys, j);
    own = starts[k] ? Part{values[k], static_cast<uint32_t>(j)}
                    : Part{op(own.sum, values[k]), own.first};
  }
  if (run_count) {  // one atomic per warp (every thread of the block is here)
    uint32_t own_starts = 0;
#pragma unroll
    for (int k = 0; k < kRunSumItems; ++k) own_starts += starts[k] ? 1u : 0u;
    const uint32_t warp_starts = warp_sum(0xFFFFFFFFu, own_starts);
    if (warp_lane() == 0 && warp_starts != 0u) atomic_add(run_count, warp_starts);
  }
  // 2. the partial run reaching this thread from the threads before it (the barrier after it
  //    frees the scan's memory for the list, and orders the counter's reset before its use)
  Part part;
  BlockScan(scan_storage).ExclusiveScan(own, part, Part{SumT{}, kNoRun}, JoinRunParts<Op>{op});
  __syncthreads();
  // 3. the records again, each run closed where it ends; then the closed runs consumed. (Their
  //    order in the list varies, but each is a different key's, so the results do not.)
  const auto list_run = [&](int64_t run_first, const SumT& sum) {
    const uint32_t slot = atomicAdd(&closed_count, 1u);
    closed_firsts[slot] = static_cast<uint32_t>(run_first);
    closed_sums[slot] = sum;
  };
#pragma unroll
  for (int k = 0; k < kRunSumItems; ++k) {
    const int64_t j = first + k;
    if (j >= tile_end) break;
    part = starts[k] ? Part{values[k], static_cast<uint32_t>(j)}
                     : Part{op(part.sum, values[k]), part.first};
    close_record(keys, count, j, tile, tile_end, part, list_run, parts);
  }
  __syncthreads();
  for (uint32_t r = threadIdx.x; r < closed_count; r += kRunSumThreads) {
    consume(static_cast<int64_t>(closed_firsts[r]), closed_sums[r]);
  }
}
#endif

template <class KeyT, class SumT, class Term, class Op, class Consume>
void sum_tiles(CpuBackend backend, const Stream& stream, const KeyT* keys, int64_t count_bound,
               const uint32_t* live_count, int64_t tiles, const Term& term, const Op& op,
               const Consume& consume, const TileParts<SumT>& parts, uint32_t* run_count) {
  const int64_t count = live_records(count_bound, live_count);
  parallel_for(backend, stream, tiles, [&](int64_t tile) {
    if (tile * kRunSumTile < count)
      sum_tile_in_order(keys, count, tile, term, op, consume, parts, run_count);
  });
}
#if defined(__CUDACC__)
template <class KeyT, class SumT, class Term, class Op, class Consume>
void sum_tiles(CudaBackend, const Stream& stream, const KeyT* keys, int64_t count_bound,
               const uint32_t* live_count, int64_t tiles, const Term& term, const Op& op,
               const Consume& consume, const TileParts<SumT>& parts, uint32_t* run_count) {
  sum_tiles_kernel<<<static_cast<unsigned>(tiles), kRunSumThreads, 0,
                     static_cast<cudaStream_t>(stream.native_handle())>>>(
      keys, count_bound, live_count, term, op, consume, parts, run_count);
  cuda_check(cudaGetLastError(), "consume_run_sums: tile kernel launch");
}
#endif

}  // namespace internal

// Calls consume(first, sum) once per run of equal keys among keys[0, count), with the index of
// the run's first record and op-sum of term(j) over the run's records j. Each tile of kRunSumTile
// records sums the runs that start and end in it and hands them over itself; a run that goes on
// past its tile leaves its partial sums for a second kernel, one thread per tile, in which the
// run's start tile adds them up in tile order. On the GPU a tile is one thread block (each thread
// sums kRunSumItems records, a segmented block scan joins the threads' partial runs, the runs
// that end in the tile are consumed one per thread); on the CPU one thread sums a tile left to
// right. Needs count < 2^32 - 1; `scratch` holds the tiles' parts (resized
// here, on the backend's device). `run_count`, when given (memory of the backend's device), is
// increased by the number of runs. `live_count`, when given (memory of the backend's device),
// says how many of the `count` records are there (known on the device only: the rest are
// ignored, and the tiles past them return at once).
template <class SumT, class Backend, class KeyT, class Term, class Op, class Consume>
void consume_run_sums(Backend backend, const Stream& stream, const KeyT* keys, int64_t count,
                      const Term& term, const Op& op, const Consume& consume,
                      Buffer<uint64_t>& scratch, uint32_t* run_count = nullptr,
                      const uint32_t* live_count = nullptr) {
  using namespace internal;
  if (count <= 0) return;
  if (count >= static_cast<int64_t>(kNoRun)) {
    throw Error("consume_run_sums: " + std::to_string(count) +
                " records, at most 2^32 - 2 fit its 32-bit record indices");
  }
  const int64_t tiles = (count + kRunSumTile - 1) / kRunSumTile;
  const TileParts<SumT> parts = carve_tile_parts<SumT>(scratch, tiles);
  sum_tiles(backend, stream, keys, count, live_count, tiles, term, op, consume, parts, run_count);
  if (tiles == 1) return;  // no run crosses a tile's edge
  // The runs crossing tile edges, each by its start tile: its tail, then the heads of the tiles
  // it passes through and of the one it ends in, in tile order. Its cost is a chain of
  // dependent loads (down to the voxel's) however few the tiles; reading several tiles ahead at
  // a time does not shorten that chain.
  parallel_for(backend, stream, tiles - 1, [=] COVOX_HD(int64_t tile) {
    // (the live records' last tile ends its last run: no walk goes past it)
    if (tile * kRunSumTile >= live_records(count, live_count)) return;
    const uint32_t run_first = parts.tail_firsts[tile];
    if (run_first == kNoRun) return;
    SumT sum = parts.tail_sums[tile];
    int64_t next = tile + 1;
    while (parts.passes[next]) sum = op(sum, parts.head_sums[next++]);
    consume(static_cast<int64_t>(run_first), op(sum, parts.head_sums[next]));
  });
}

}  // namespace covox

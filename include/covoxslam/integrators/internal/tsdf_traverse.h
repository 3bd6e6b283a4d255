#pragma once
// Stage 2b of a TSDF frame: every ray piece (tsdf_kernels.h) emits one visit record (key, value)
// per voxel it visits, into its own range [piece_offsets[p], piece_offsets[p + 1]) of the record
// arrays. The value is the distance update itself (no colour) or one ColorVisit word: in the
// band the ray's index, the update recomputed from ray and voxel where the records are summed
// (VoxelUpdateOfRecord); in free space the visit's weight. The per-voxel arithmetic is one
// function for both backends; the CPU writes each piece's records directly, a CUDA thread block
// gathers its pieces' records in shared memory and copies them out with coalesced stores
// (directly when they do not fit). With free-space sums only the band's records are kept
// (BandRecords): compacted afterwards on the CPU, as they are copied out on the GPU.
#include <algorithm>
#include <cstdint>

#include "covoxslam/core/atomics.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/sorted_search.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox::integrators::tsdf {

// Ray i's weight factor (1 unless the frame gives one per ray, as merged rays do).
COVOX_HD_INLINE float ray_weight_of(const FrameUpdates& frame, uint32_t i) {
  return frame.ray_weights ? frame.ray_weights[i] : 1.0f;
}

// What a ray (with its weight factor) contributes to a voxel it visits: the projective distance
// clamped to the truncation band (free space in front of it), weighted (zero weight behind the
// band or dropped off). `takes_color` tells whether the visit also takes the ray's colour: inside
// the band of a surface ray, with weight (voxblox's rule). The ray comes in by value, loaded once
// per piece by the traverse (the record stores in between could alias it, so a lookup here would
// be repeated for every voxel). A visit whose distance is the truncation (free space, clearing
// rays) contributes (weight * truncation, weight) and no colour: free_space_update() below.
COVOX_HD_INLINE DistanceUpdate voxel_update(const FrameUpdates& frame, const RaySegment& ray,
                                            float ray_weight, const Index3D& voxel,
                                            float truncation, bool* takes_color) {
  const float voxel_size = frame.voxel_size;
  const Vec3f center((voxel.x + 0.5f) * voxel_size, (voxel.y + 0.5f) * voxel_size,
                     (voxel.z + 0.5f) * voxel_size);
  const bool clearing = ray.kind == kClearingRay;
  float distance = clearing ? truncation : (ray.surface - center).dot(ray.direction);
  float weight = 0.0f;
  if (distance >= -truncation) {
    if (distance > truncation) distance = truncation;
    weight = ray_weight * update_weight(frame.weight_parameters, ray.range_m, distance);
  }
  *takes_color = !clearing && fabsf(distance) < truncation && weight > 0.0f;
  DistanceUpdate update;
  update.weighted_distance = weight * distance;
  update.weight = weight;
  return update;
}

// The update of a visit at the truncation distance (free space) from its weight alone: what
// voxel_update() computes there (the same product, so the same float).
COVOX_HD_INLINE DistanceUpdate free_space_update(float weight, float truncation) {
  DistanceUpdate update;
  update.weighted_distance = weight * truncation;
  update.weight = weight;
  return update;
}

// A free-space visit: its distance is the truncation (clamped, or a clearing ray's) and it takes
// no colour. (A visit without colour has its distance at +truncation or -truncation, or no
// weight: the product tells the first.)
COVOX_HD_INLINE bool is_free_space_visit(const DistanceUpdate& update, bool takes_color,
                                         float truncation) {
  return !takes_color && update.weight >= 0.0f &&
         update.weighted_distance == update.weight * truncation;
}

// A record's value (see above): the update without colour; with colour (ColorVisit,
// tsdf_kernels.h) the weight of a free-space visit, else the ray's index flagged as a band visit.
COVOX_HD_INLINE void make_record_value(const DistanceUpdate& update, bool, uint32_t,
                                       DistanceUpdate* value) {
  *value = update;
}
COVOX_HD_INLINE void make_record_value(const DistanceUpdate& update, bool free_space, uint32_t ray,
                                       ColorVisit* value) {
  value->word = free_space ? bits_of_float(update.weight) : (ray | ColorVisit::kBandVisitBit);
}

// The records of piece p, handed to emit(out, key, value) with out = the record's index in the
// frame's record arrays.
template <class KeyT, class ValueT>
struct PieceTraversal {
  FrameUpdates frame;
  KeyT zero_weight_key;
  const uint32_t* piece_offsets;  // each piece's first record (exclusive scan of its voxel count)
  float truncation;
  // When given, one flag per block of the frame's box (the codec's block number), set for every
  // block that a kept record (weight, inside the box) falls in: the frame's blocks, known before
  // the records are sorted (internal/tsdf_stage_blocks.h).
  uint32_t* block_marks = nullptr;
  // When given (with block_marks), one fixed-point weight sum per key of the frame's box: a kept
  // free-space visit adds its weight there (weight_units, tsdf_kernels.h) and leaves a record with
  // the zero-weight key, which the compaction drops; only the band's visits are sorted and reduced.
  // A free-space visit outside the box is counted in *free_out_of_range instead.
  uint64_t* free_space_sums = nullptr;
  uint64_t* free_out_of_range = nullptr;
  bool accumulate_free_space =
      true;  // false: free-space visits only leave their zero-weight record
  // When given (instead of free_space_sums), every kept visit adds its update to its voxel's cell
  // (tsdf_kernels.h) and leaves a zero-weight record; the traverse then keeps no record at all
  // (sum_ray_groups). Visits outside the box are counted in *free_out_of_range.
  VoxelSumCells sum_cells;

  // Piece p of the piece table, its records from piece_offsets[p] on.
  template <class Emit>
  COVOX_HD_INLINE void operator()(int64_t p, Emit&& emit) const {
    if (p >= *frame.piece_total) return;
    const RayPiece piece = frame.pieces[p];
    const RaySegment ray = frame.rays[piece.ray];
    // The piece's cut voxels: from the piece table where it has them (its own first voxel, and
    // the next piece's or the ray's last voxel), else computed.
    if (frame.piece_first_voxels) {
      const Index3D last = piece.index + 1 == piece.pieces
                               ? voxel_of(ray.end, frame.inverse_voxel_size)
                               : frame.piece_first_voxels[p + 1];
      visit_piece(ray, piece.ray, piece.index, piece.pieces, frame.piece_first_voxels[p], last,
                  piece_offsets[p], emit);
    } else {
      visit_piece(ray, piece.ray, piece.index, piece.pieces, piece_offsets[p], emit);
    }
  }
  // Piece k of ray i's `pieces`, its cut voxels computed (records from `out` on).
  template <class Emit>
  COVOX_HD_INLINE void visit_piece(const RaySegment& ray, uint32_t i, uint32_t k, uint32_t pieces,
                                   uint32_t out, Emit&& emit) const {
    const RayEndVoxels ends = ray_end_voxels(ray, frame.inverse_voxel_size);
    visit_piece(ray, i, k, pieces, ray_cut_voxel(ray, ends, k, pieces, frame.inverse_voxel_size),
                ray_cut_voxel(ray, ends, k + 1, pieces, frame.inverse_voxel_size), out, emit);
  }
  template <class Emit>
  COVOX_HD_INLINE void visit_piece(const RaySegment& ray, uint32_t i, uint32_t k, uint32_t pieces,
                                   const Index3D& first, const Index3D& last, uint32_t out,
                                   Emit&& emit) const {
    const float ray_weight = ray_weight_of(frame, i);
    uint64_t marked =
        ~uint64_t(0);  // the block this piece marked last (a piece spans one to three)
    traverse_ray_piece(
        ray, k, pieces, first, last, frame.inverse_voxel_size, [&](const Index3D& voxel) {
          bool takes_color = false;
          const DistanceUpdate update =
              voxel_update(frame, ray, ray_weight, voxel, truncation, &takes_color);
          const bool free_space = is_free_space_visit(update, takes_color, truncation);
          ValueT value;
          make_record_value(update, free_space, i, &value);
          uint64_t key = update.weight > 0.0f ? frame.codec.key(voxel)
                                              : static_cast<uint64_t>(zero_weight_key);
          if (block_marks && key < frame.codec.out_of_range_key &&
              frame.codec.block_part(key) != marked) {
            marked = frame.codec.block_part(key);
            mark_flag(&block_marks[marked]);
          }
          if ((sum_cells.words || (free_space_sums && free_space)) && update.weight > 0.0f) {
            if (accumulate_free_space && key < frame.codec.out_of_range_key) {
              if (sum_cells.words) {
                const Rgb8 color = takes_color ? color_of(frame.colors, frame.intensities,
                                                          frame.grey_per_intensity, i)
                                               : Rgb8{};
                sum_cells.add(key, update, free_space, takes_color, color);
              } else {
                atomic_add(&free_space_sums[key], weight_units(update.weight));
              }
            } else if (accumulate_free_space) {
              atomic_add(free_out_of_range, uint64_t(1));
            }
            key = static_cast<uint64_t>(zero_weight_key);
          }
          emit(out, static_cast<KeyT>(key), value);
          ++out;
        });
  }
};

// Where the records go: keys and values (which the sort moves together).
template <class KeyT, class ValueT>
struct RecordArrays {
  KeyT* keys;
  ValueT* values;
  COVOX_HD_INLINE void operator()(uint32_t out, KeyT key, const ValueT& value) const {
    keys[out] = key;
    values[out] = value;
  }
};

// A coloured frame's record j as the reduction reads it from the sorted records: the update its
// ray makes to its voxel, with the ray's colour when the visit takes it. A record to drop (its key
// at or above the codec's out-of-range key; they sort last) reads as empty: its run is counted,
// not written.
template <class KeyT>
struct VoxelUpdateOfRecord {
  FrameUpdates frame;
  const KeyT* keys;
  const ColorVisit* visits;
  KeyT first_dropped_key;
  float truncation;
  COVOX_HD_INLINE VoxelUpdate operator()(int64_t j) const {
    const KeyT key = keys[j];
    if (key >= first_dropped_key) return VoxelUpdate{};
    const uint32_t word = visits[j].word;
    VoxelUpdate sum;
    if (!(word & ColorVisit::kBandVisitBit)) {  // free space: the weight itself
      const DistanceUpdate update = free_space_update(float_of_bits(word), truncation);
      sum.weighted_distance = update.weighted_distance;
      sum.weight = update.weight;
      return sum;
    }
    const uint32_t i = word & ~ColorVisit::kBandVisitBit;
    bool takes_color = false;
    const DistanceUpdate update = voxel_update(frame, frame.rays[i], ray_weight_of(frame, i),
                                               frame.codec.voxel(key), truncation, &takes_color);
    sum.weighted_distance = update.weighted_distance;
    sum.weight = update.weight;
    if (takes_color) {
      const Rgb8 color = color_of(frame.colors, frame.intensities, frame.grey_per_intensity, i);
      sum.weighted_r = update.weight * color.r;
      sum.weighted_g = update.weight * color.g;
      sum.weighted_b = update.weight * color.b;
      sum.color_weight = update.weight;
    }
    return sum;
  }
};

// With free-space sums (PieceTraversal::free_space_sums) only the band's records are wanted: they
// go compacted, in visit order, into the first places of `keys` / `values`, at most `bound` of
// them, and their count to *kept (memory of the backend's device). The places after them, up to
// the bound, hold keys that sort last and that stage 5 does not read (its live count is *kept):
// the zero-weight key on the CPU, all bits set on the GPU (a memset).
template <class KeyT, class ValueT>
struct BandRecords {
  KeyT* keys = nullptr;  // null: every record goes to the RecordArrays
  ValueT* values = nullptr;
  int64_t bound = 0;
  uint32_t* kept = nullptr;
  uint32_t* ranks = nullptr;  // the CPU's compaction scan: visits + 1 places
};

// The CPU twin writes every record at its place (the zero-weight key for free-space visits) and
// then compacts the band's: a scan of the kept flags, a scatter.
template <class KeyT, class ValueT>
void traverse_pieces(CpuBackend backend, const Stream& stream, int64_t piece_bound,
                     int64_t total_updates, const PieceTraversal<KeyT, ValueT>& traversal,
                     const RecordArrays<KeyT, ValueT>& arrays,
                     const BandRecords<KeyT, ValueT>& band = {}) {
  parallel_for(backend, stream, piece_bound, [&](int64_t p) { traversal(p, arrays); });
  if (!band.keys) return;
  const KeyT dropped = traversal.zero_weight_key;
  const KeyT* visit_keys = arrays.keys;
  const ValueT* visit_values = arrays.values;
  uint32_t* ranks = band.ranks;
  exclusive_scan_of(
      backend, stream, total_updates + 1,
      [=](int64_t j) -> uint32_t {
        return j < total_updates && visit_keys[j] != dropped ? 1u : 0u;
      },
      ranks);
  const uint32_t kept = ranks[total_updates];
  *band.kept = kept;
  parallel_for(backend, stream, std::max(total_updates, band.bound), [=](int64_t j) {
    if (j < total_updates && visit_keys[j] != dropped && ranks[j] < band.bound) {
      band.keys[ranks[j]] = visit_keys[j];
      band.values[ranks[j]] = visit_values[j];
    }
    if (j < band.bound && j >= kept) {
      band.keys[j] = dropped;
      band.values[j] = ValueT{};
    }
  });
}

// With every visit summed no record is kept, and the rays are walked in groups of kRayGroupRays
// consecutive rays (neighbouring pixels or beams: their rays leave the sensor side by side), one
// GPU warp per group and piece index ("level"): lane l walks piece k of the group's ray l, so that
// at each step the lanes visit voxels at about the same distance along neighbouring rays. It needs
// no piece table (and no scan to build one), only the rays' piece counts. Every group gets as many
// levels as the frame's longest ray has pieces (the merge's tally knows it), so work item w is
// level w % levels of group w / levels: a warp whose lanes' rays are all shorter leaves at once,
// and no item searches for its group.
constexpr int kRayGroupRays = 32;
struct RayGroups {
  const uint32_t* ray_pieces;  // each ray's piece count
  uint32_t levels;             // the most pieces of any ray: each group's levels
  int64_t rays;
  int64_t groups;
  COVOX_HD_INLINE int64_t items() const { return groups * static_cast<int64_t>(levels); }
};
COVOX_HD_INLINE int64_t ray_group_count(int64_t rays) {
  return (rays + kRayGroupRays - 1) / kRayGroupRays;
}
// Work item w (level k of group g): lane `lane` walks piece k of the group's ray `lane`, if that
// ray has that many pieces.
template <class KeyT, class ValueT>
COVOX_HD_INLINE void sum_ray_group_piece(const PieceTraversal<KeyT, ValueT>& traversal,
                                         const RayGroups& groups, int64_t w, int lane) {
  const uint32_t levels = groups.levels;
  // (a 32-bit division where the items allow, as they always do in practice: a 64-bit one is a
  // long software sequence on the GPU)
  const int64_t g = w <= int64_t(UINT32_MAX)
                        ? static_cast<int64_t>(static_cast<uint32_t>(w) / levels)
                        : static_cast<int64_t>(static_cast<uint64_t>(w) / levels);
  const uint32_t k = static_cast<uint32_t>(w - g * levels);
  const int64_t i = g * kRayGroupRays + lane;
  if (i >= groups.rays) return;
  const uint32_t pieces = groups.ray_pieces[i];
  if (k >= pieces) return;
  // The ray copied (see voxel_update): passed by reference into the frame's array, its fields
  // would be loaded again at every visit, as the atomics in between might alias them.
  const RaySegment ray = traversal.frame.rays[i];
  traversal.visit_piece(ray, static_cast<uint32_t>(i), k, pieces, 0u,
                        [](uint32_t, KeyT, const ValueT&) {});
}
// The CPU twin: one call per work item, its lanes in turn.
template <class KeyT, class ValueT>
void sum_ray_groups(CpuBackend backend, const Stream& stream,
                    const PieceTraversal<KeyT, ValueT>& traversal, const RayGroups& groups) {
  if (!traversal.sum_cells.words)
    throw Error("TSDF traverse: every visit's sum asked without cells to add it to");
  parallel_for(backend, stream, groups.items(), [&](int64_t w) {
    for (int lane = 0; lane < kRayGroupRays; ++lane)
      sum_ray_group_piece(traversal, groups, w, lane);
  });
}

#if defined(__CUDACC__)
namespace detail {
constexpr int kRayGroupThreads = 128;
// One warp per work item, in a grid-stride loop up to the items' total (on the device); no
// register cap beyond the launch bounds (fewer registers for more resident warps spill).
template <class KeyT, class ValueT>
__global__ void __launch_bounds__(kRayGroupThreads)
    sum_ray_groups_kernel(PieceTraversal<KeyT, ValueT> traversal, RayGroups groups) {
  static_assert(kRayGroupRays == 32, "one lane per ray of a group");
  const int64_t items = groups.items();
  const int64_t warps = static_cast<int64_t>(gridDim.x) * (kRayGroupThreads / 32);
  for (int64_t w = (static_cast<int64_t>(blockIdx.x) * kRayGroupThreads + threadIdx.x) / 32;
       w < items; w += warps) {
    sum_ray_group_piece(traversal, groups, w, static_cast<int>(threadIdx.x & 31u));
  }
}
}  // namespace detail

template <class KeyT, class ValueT>
void sum_ray_groups(CudaBackend, const Stream& stream,
                    const PieceTraversal<KeyT, ValueT>& traversal, const RayGroups& groups) {
  if (!traversal.sum_cells.words)
    throw Error("TSDF traverse: every visit's sum asked without cells to add it to");
  if (groups.items() <= 0) return;
  constexpr int64_t kWarpsPerBlock = detail::kRayGroupThreads / 32;
  const int64_t blocks =
      std::min<int64_t>((groups.items() + kWarpsPerBlock - 1) / kWarpsPerBlock, int64_t(1) << 16);
  detail::sum_ray_groups_kernel<KeyT, ValueT>
      <<<static_cast<unsigned>(blocks), detail::kRayGroupThreads, 0,
         static_cast<cudaStream_t>(stream.native_handle())>>>(traversal, groups);
  cuda_check(cudaGetLastError(), "TSDF ray groups kernel launch");
}
#endif

#if defined(__CUDACC__)
namespace detail {
constexpr int kTraverseThreads = 128;
constexpr int kTraverseSharedBytes = 45 * 1024;
// A block's 128 pieces of at most ~kVoxelsPerPiece voxels hold about 1000 records; room for
// 1.5 times that is enough, and a block that needs more writes directly. Staging no more than
// that keeps the shared memory per block small (18 KB for 8-byte updates instead of 45 KB), so
// more blocks run per multiprocessor and hide the traverse's memory latency.
constexpr int kMaxStagedRecords = 3 * kTraverseThreads * kVoxelsPerPiece / 2;

// With BandRecords: the block's place among the band's records (a block scan of the threads'
// counts, then a decoupled look-back over the blocks before it) plus this thread's offset in it.
// The last block writes the total. Called by every thread of the block.
template <class KeyT, class ValueT>
__device__ uint32_t band_place(uint32_t own, const BandRecords<KeyT, ValueT>& band,
                               const ScanDescriptors& descriptors) {
  using BlockScan = cub::BlockScan<uint32_t, kTraverseThreads>;
  __shared__ typename BlockScan::TempStorage scan_storage;
  __shared__ uint32_t block_prefix;
  uint32_t thread_offset = 0, block_total = 0;
  BlockScan(scan_storage).ExclusiveSum(own, thread_offset, block_total);
  if (threadIdx.x < 32) {
    const uint32_t prefix = covox::internal::look_back_tile_prefix(
        descriptors.words, descriptors.epoch, blockIdx.x, block_total);
    if (threadIdx.x == 0) {
      block_prefix = prefix;
      if (blockIdx.x == gridDim.x - 1) *band.kept = prefix + block_total;
    }
  }
  __syncthreads();
  return block_prefix + thread_offset;
}

// With free-space sums (band.keys given) the block keeps only the band's records and copies them
// out compacted: its staged records read in chunks, one per thread, counted, placed (band_place)
// and stored; a block whose records do not fit counts its band visits in a first walk (no sums),
// and writes them directly in a second. (The CPU writes every record, then compacts: two more
// passes over the records, which this saves.)
template <class KeyT, class ValueT>
__global__ void staged_traverse_kernel(PieceTraversal<KeyT, ValueT> traversal,
                                       RecordArrays<KeyT, ValueT> arrays,
                                       BandRecords<KeyT, ValueT> band, ScanDescriptors descriptors,
                                       int64_t piece_bound, uint32_t total_updates) {
  constexpr int kFitting = kTraverseSharedBytes / static_cast<int>(sizeof(ValueT) + sizeof(KeyT));
  constexpr int kCapacity = kFitting < kMaxStagedRecords ? kFitting : kMaxStagedRecords;
  __shared__ alignas(16) ValueT staged_values[kCapacity];
  __shared__ alignas(16) KeyT staged_keys[kCapacity];
  const int64_t first = static_cast<int64_t>(blockIdx.x) * kTraverseThreads;
  const int64_t p = first + threadIdx.x;
  const int64_t after = first + kTraverseThreads;
  // The block's pieces are consecutive, so their records fill one range of the update arrays.
  const uint32_t base = traversal.piece_offsets[first];
  const uint32_t end = after < piece_bound ? traversal.piece_offsets[after] : total_updates;
  const uint32_t size = end - base;
  const KeyT dropped = traversal.zero_weight_key;
  if (size > static_cast<uint32_t>(kCapacity)) {  // the same for the whole block
    if (!band.keys) {
      if (p < piece_bound) traversal(p, arrays);
      return;
    }
    uint32_t own = 0;
    if (p < piece_bound) {
      PieceTraversal<KeyT, ValueT> counting = traversal;
      counting.accumulate_free_space = false;
      counting(p, [&](uint32_t, KeyT key, const ValueT&) { own += key != dropped ? 1u : 0u; });
    }
    uint32_t next = band_place(own, band, descriptors);
    if (p < piece_bound) {
      traversal(p, [&](uint32_t, KeyT key, const ValueT& value) {
        if (key == dropped) return;
        if (next < band.bound) {
          band.keys[next] = key;
          band.values[next] = value;
        }
        ++next;
      });
    }
    return;
  }
  if (p < piece_bound) {
    traversal(p, [&](uint32_t out, KeyT key, const ValueT& value) {
      staged_keys[out - base] = key;
      staged_values[out - base] = value;
    });
  }
  __syncthreads();
  if (!band.keys) {
    for (uint32_t j = threadIdx.x; j < size; j += kTraverseThreads) {
      arrays.keys[base + j] = staged_keys[j];
      arrays.values[base + j] = staged_values[j];
    }
    return;
  }
  const uint32_t chunk = (size + kTraverseThreads - 1) / kTraverseThreads;
  const uint32_t chunk_begin = min(size, threadIdx.x * chunk),
                 chunk_end = min(size, chunk_begin + chunk);
  uint32_t own = 0;
  for (uint32_t j = chunk_begin; j < chunk_end; ++j) own += staged_keys[j] != dropped ? 1u : 0u;
  uint32_t next = band_place(own, band, descriptors);
  for (uint32_t j = chunk_begin; j < chunk_end; ++j) {
    if (staged_keys[j] == dropped) continue;
    if (next < band.bound) {
      band.keys[next] = staged_keys[j];
      band.values[next] = staged_values[j];
    }
    ++next;
  }
}
}  // namespace detail

template <class KeyT, class ValueT>
void traverse_pieces(CudaBackend, const Stream& stream, int64_t piece_bound, int64_t total_updates,
                     const PieceTraversal<KeyT, ValueT>& traversal,
                     const RecordArrays<KeyT, ValueT>& arrays,
                     const BandRecords<KeyT, ValueT>& band = {}) {
  if (band.keys && piece_bound <= 0)
    throw Error("TSDF traverse: band records asked of a frame without pieces");
  if (piece_bound <= 0) return;
  const int64_t blocks = (piece_bound + detail::kTraverseThreads - 1) / detail::kTraverseThreads;
  ScanDescriptors descriptors;
  if (band.keys) {
    set_bytes(band.keys, Device::kCuda, 0xFF, static_cast<size_t>(band.bound) * sizeof(KeyT),
              stream);
    if (blocks > 1) descriptors = single_pass_scan_descriptors(stream, blocks);
  }
  detail::staged_traverse_kernel<KeyT, ValueT>
      <<<static_cast<unsigned>(blocks), detail::kTraverseThreads, 0,
         static_cast<cudaStream_t>(stream.native_handle())>>>(
          traversal, arrays, band, descriptors, piece_bound, static_cast<uint32_t>(total_updates));
  cuda_check(cudaGetLastError(), "TSDF traverse kernel launch");
}
#endif

}  // namespace covox::integrators::tsdf

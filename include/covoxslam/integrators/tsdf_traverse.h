#pragma once
// Step 2b of a TSDF frame: every ray piece (tsdf_kernels.h) emits one (key, update) per voxel it
// visits, into its own contiguous range [piece_offsets[p], piece_offsets[p + 1]) of the update
// arrays. The per-voxel arithmetic is one __host__ __device__ functor for both backends; only how
// the records reach memory differs:
// - CPU: each OpenMP thread writes its pieces' records directly (contiguous per thread).
// - CUDA: one thread per piece would make every warp store to 32 scattered places (each thread's
//   run of ~8 records), so a block first collects its pieces' records in shared memory, where the
//   ranges of consecutive pieces are consecutive, and then copies them out with coalesced
//   stores. A block whose records do not fit (pieces much longer than kVoxelsPerPiece, which the
//   cut rule does not produce) writes directly, as the CPU does.
#include <cstdint>

#include "covoxslam/core/device.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/tsdf_kernels.h"

namespace covox {
namespace tsdf {

// The records of piece p, handed to emit(out, key, update) with out = the record's index in the
// frame's update arrays.
template <class UpdateT, class KeyT>
struct PieceTraversal {
  FrameUpdates frame;
  KeyT zero_weight_key;
  const uint32_t* piece_offsets;  // each piece's first record (exclusive scan of its voxel count)
  float truncation;

  template <class Emit>
  COVOX_HD_INLINE void operator()(int64_t p, Emit&& emit) const {
    if (p >= *frame.piece_total) return;
    const RayPiece piece = frame.pieces[p];
    const int64_t i = piece.ray;
    const RaySegment ray = frame.rays[i];
    uint32_t out = piece_offsets[p];
    const bool clearing = ray.kind == kClearingRay;
    const Rgb8 color = frame.colors ? frame.colors[i]
                                    : (frame.intensities ? intensity_to_grey(frame.intensities[i], frame.grey_per_intensity)
                                                         : Rgb8{});
    const float ray_weight = frame.ray_weights ? frame.ray_weights[i] : 1.0f;
    const float voxel_size = frame.voxel_size;
    traverse_ray_piece(ray, piece.index, piece.pieces, frame.inverse_voxel_size, [&](const Index3D& voxel) {
      const Vec3f center((voxel.x + 0.5f) * voxel_size, (voxel.y + 0.5f) * voxel_size, (voxel.z + 0.5f) * voxel_size);
      float distance = clearing ? truncation : (ray.surface - center).dot(ray.direction);
      float weight = 0.0f;
      if (distance >= -truncation) {
        if (distance > truncation) distance = truncation;
        weight = ray_weight * update_weight(frame.weight_parameters, ray.range_m, distance);
      }
      UpdateT update;
      update.weighted_distance = weight * distance;
      update.weight = weight;
      if (!clearing && fabsf(distance) < truncation && weight > 0.0f) set_update_color(update, weight, color);
      emit(out, weight > 0.0f ? static_cast<KeyT>(frame.codec.key(voxel)) : zero_weight_key, update);
      ++out;
    });
  }
};

// Where the records go: keys, updates and (when the updates are gathered after the sort rather
// than sorted along) the identity order.
template <class UpdateT, class KeyT>
struct UpdateArrays {
  KeyT* keys;
  UpdateT* updates;
  uint32_t* order;  // nullptr when the updates travel with their keys
  COVOX_HD_INLINE void operator()(uint32_t out, KeyT key, const UpdateT& update) const {
    keys[out] = key;
    updates[out] = update;
    if (order) order[out] = out;
  }
};

template <class UpdateT, class KeyT>
void traverse_pieces(CpuBackend backend, const Stream& stream, int64_t piece_bound, int64_t,
                     const PieceTraversal<UpdateT, KeyT>& traversal, const UpdateArrays<UpdateT, KeyT>& arrays) {
  parallel_for(backend, stream, piece_bound, [&](int64_t p) { traversal(p, arrays); });
}

#if defined(__CUDACC__)
namespace detail {
constexpr int kTraverseThreads = 128;
constexpr int kTraverseSharedBytes = 45 * 1024;

template <class UpdateT, class KeyT>
__global__ void staged_traverse_kernel(PieceTraversal<UpdateT, KeyT> traversal, UpdateArrays<UpdateT, KeyT> arrays,
                                       int64_t piece_bound, uint32_t total_updates) {
  constexpr int kCapacity = kTraverseSharedBytes / static_cast<int>(sizeof(UpdateT) + sizeof(KeyT));
  __shared__ alignas(16) unsigned char storage[kCapacity * (sizeof(UpdateT) + sizeof(KeyT))];
  UpdateT* staged_updates = reinterpret_cast<UpdateT*>(storage);
  KeyT* staged_keys = reinterpret_cast<KeyT*>(storage + kCapacity * sizeof(UpdateT));
  const int64_t first = static_cast<int64_t>(blockIdx.x) * kTraverseThreads;
  const int64_t p = first + threadIdx.x;
  const int64_t after = first + kTraverseThreads;
  // The block's pieces are consecutive, so their records fill one range of the update arrays.
  const uint32_t base = traversal.piece_offsets[first];
  const uint32_t end = after < piece_bound ? traversal.piece_offsets[after] : total_updates;
  const uint32_t size = end - base;
  if (size > static_cast<uint32_t>(kCapacity)) {  // the same for the whole block
    if (p < piece_bound) traversal(p, arrays);
    return;
  }
  if (p < piece_bound) {
    traversal(p, [&](uint32_t out, KeyT key, const UpdateT& update) {
      staged_keys[out - base] = key;
      staged_updates[out - base] = update;
    });
  }
  __syncthreads();
  for (uint32_t j = threadIdx.x; j < size; j += kTraverseThreads) {
    arrays.keys[base + j] = staged_keys[j];
    arrays.updates[base + j] = staged_updates[j];
    if (arrays.order) arrays.order[base + j] = base + j;
  }
}
}  // namespace detail

template <class UpdateT, class KeyT>
void traverse_pieces(CudaBackend, const Stream& stream, int64_t piece_bound, int64_t total_updates,
                     const PieceTraversal<UpdateT, KeyT>& traversal, const UpdateArrays<UpdateT, KeyT>& arrays) {
  if (piece_bound <= 0) return;
  const int64_t blocks = (piece_bound + detail::kTraverseThreads - 1) / detail::kTraverseThreads;
  detail::staged_traverse_kernel<UpdateT, KeyT>
      <<<static_cast<unsigned>(blocks), detail::kTraverseThreads, 0, static_cast<cudaStream_t>(stream.native_handle())>>>(
          traversal, arrays, piece_bound, static_cast<uint32_t>(total_updates));
  cuda_check(cudaGetLastError(), "TSDF traverse kernel launch");
}
#endif

}  // namespace tsdf
}  // namespace covox

#pragma once
// Reductions over the lanes of a GPU warp that run a kernel body together, so that many threads
// adding to the same counter or bundle issue one atomic per warp instead of one each (atomics on
// one address serialise in the GPU's L2: the many pixels of a depth image that add to one bundle
// would otherwise wait for each other). On the host a "warp" is the calling thread alone, so
// the same kernel body does one atomic per call there.
//
// `lanes` is the mask of lanes taking part (warp_lanes() at the call site: a parallel_for's last
// warp may be partial); every lane in it must make the same calls in the same order.
#include <cstdint>

#include "covoxslam/core/bit_count.h"
#include "covoxslam/core/macros.h"

namespace covox {

namespace internal {
#if COVOX_DEVICE_CODE
// sm_80 and later reduce over a warp in one instruction; before that, every lane reads every
// other lane's value in turn (a shuffle with the same mask in every lane, valid for any mask).
template <class T, class Op>
__device__ __forceinline__ T warp_fold(uint32_t lanes, T value, Op op) {
  T result = __shfl_sync(lanes, value, __ffs(lanes) - 1);
  for (uint32_t rest = lanes & (lanes - 1u); rest != 0u; rest &= rest - 1u) {
    result = op(result, __shfl_sync(lanes, value, __ffs(rest) - 1));
  }
  return result;
}
struct FoldAdd {
  template <class T>
  __device__ T operator()(T a, T b) const {
    return a + b;
  }
};
struct FoldMin {
  template <class T>
  __device__ T operator()(T a, T b) const {
    return a < b ? a : b;
  }
};
struct FoldMax {
  template <class T>
  __device__ T operator()(T a, T b) const {
    return a > b ? a : b;
  }
};
#endif
}  // namespace internal

// The lanes running this call together (the host: lane 0 alone).
COVOX_HD_INLINE uint32_t warp_lanes() {
#if COVOX_DEVICE_CODE
  return __activemask();
#else
  return 1u;
#endif
}

COVOX_HD_INLINE int warp_lane() {
#if COVOX_DEVICE_CODE
  return static_cast<int>(threadIdx.x & 31u);
#else
  return 0;
#endif
}

// The lowest lane of a non-empty mask.
COVOX_HD_INLINE int warp_first_lane(uint32_t mask) {
#if COVOX_DEVICE_CODE
  return __ffs(mask) - 1;
#else
  return mask ? __builtin_ctz(mask) : -1;
#endif
}

// The lanes (of `lanes`) for which `predicate` holds.
COVOX_HD_INLINE uint32_t warp_ballot(uint32_t lanes, bool predicate) {
#if COVOX_DEVICE_CODE
  return __ballot_sync(lanes, predicate);
#else
  (void)lanes;
  return predicate ? 1u : 0u;
#endif
}

// The lanes (of `lanes`) whose `key` equals this lane's: each group of equal keys reduces among
// itself (pass the result as the `lanes` of the reductions below), all groups at once.
COVOX_HD_INLINE uint32_t warp_match(uint32_t lanes, uint64_t key) {
#if COVOX_DEVICE_CODE
  return __match_any_sync(lanes, static_cast<unsigned long long>(key));
#else
  (void)lanes;
  (void)key;
  return 1u;
#endif
}

// `value` as lane `source` holds it (32- or 64-bit).
template <class T>
COVOX_HD_INLINE T warp_broadcast(uint32_t lanes, T value, int source) {
#if COVOX_DEVICE_CODE
  return __shfl_sync(lanes, value, source);
#else
  (void)lanes;
  (void)source;
  return value;
#endif
}

// Sums and extremes over `lanes`, the same in every lane: 32-bit values (unsigned or int) in
// one instruction from sm_80 on.
#if COVOX_DEVICE_CODE && __CUDA_ARCH__ >= 800
#define COVOX_WARP_REDUCE_32(intrinsic, fold) return intrinsic(lanes, value)
#elif COVOX_DEVICE_CODE
#define COVOX_WARP_REDUCE_32(intrinsic, fold) return internal::warp_fold(lanes, value, fold{})
#else
#define COVOX_WARP_REDUCE_32(intrinsic, fold) \
  (void)lanes;                                \
  return value
#endif
template <class T>
COVOX_HD_INLINE T warp_min(uint32_t lanes, T value) {
  static_assert(sizeof(T) == 4, "warp_min: 32-bit values");
  COVOX_WARP_REDUCE_32(__reduce_min_sync, internal::FoldMin);
}
template <class T>
COVOX_HD_INLINE T warp_max(uint32_t lanes, T value) {
  static_assert(sizeof(T) == 4, "warp_max: 32-bit values");
  COVOX_WARP_REDUCE_32(__reduce_max_sync, internal::FoldMax);
}
COVOX_HD_INLINE uint32_t warp_sum(uint32_t lanes, uint32_t value) {
  COVOX_WARP_REDUCE_32(__reduce_add_sync, internal::FoldAdd);
}
#undef COVOX_WARP_REDUCE_32

// 64-bit sums (modulo 2^64, so signed values sum right in two's complement): the hardware sums
// 32-bit words, so the value goes through in four 16-bit pieces, whose sums over 32 lanes cannot
// carry out of 32 bits.
COVOX_HD_INLINE uint64_t warp_sum(uint32_t lanes, uint64_t value) {
#if COVOX_DEVICE_CODE && __CUDA_ARCH__ < 800
  return internal::warp_fold(lanes, value, internal::FoldAdd{});
#elif COVOX_DEVICE_CODE
  uint64_t sum = 0;
  for (int piece = 0; piece < 4; ++piece) {
    const uint32_t part = static_cast<uint32_t>(value >> (16 * piece)) & 0xFFFFu;
    sum += static_cast<uint64_t>(warp_sum(lanes, part)) << (16 * piece);
  }
  return sum;
#else
  (void)lanes;
  return value;
#endif
}

// The number of lanes in a mask (the host's "warp": 1).
COVOX_HD_INLINE uint32_t warp_count(uint32_t lanes) { return count_bits(lanes); }

// The 64-bit sum over `lanes` of values that all lie within 2^31 of each other (points of one
// voxel, say): the lowest lane's value times the lane count plus the sum of the differences,
// which go through in two 32-bit reductions (a 16-bit piece and the signed rest, neither of
// which can overflow over 32 lanes) instead of four. Lanes of different groups reduce in turn,
// so each reduction saved counts once per group.
COVOX_HD_INLINE int64_t warp_sum_clustered(uint32_t lanes, int64_t value) {
#if COVOX_DEVICE_CODE && __CUDA_ARCH__ >= 800
  const long long reference = __shfl_sync(lanes, static_cast<long long>(value), __ffs(lanes) - 1);
  const int64_t difference = value - reference;
  const uint32_t low = static_cast<uint32_t>(difference) & 0xFFFFu;
  const int high = static_cast<int>(difference >> 16);  // floor: difference = high * 2^16 + low
  const uint32_t low_sum = __reduce_add_sync(lanes, low);
  const int high_sum = __reduce_add_sync(lanes, high);
  return reference * __popc(lanes) + static_cast<int64_t>(high_sum) * 65536 +
         static_cast<int64_t>(low_sum);
#else
  return static_cast<int64_t>(warp_sum(lanes, static_cast<uint64_t>(value)));
#endif
}

}  // namespace covox

#pragma once
// Atomics callable from the same kernel body on both backends: CUDA's atomic* in device code,
// the GCC/Clang __atomic builtins on the host (OpenMP threads).
#include <cstdint>

#include "covoxslam/core/macros.h"

namespace covox {

// Compare-and-swap; returns the value that was at `address` before (== expected on success).
COVOX_HD_INLINE uint64_t atomic_compare_exchange(uint64_t* address, uint64_t expected,
                                                 uint64_t desired) {
#if COVOX_DEVICE_CODE
  return atomicCAS(reinterpret_cast<unsigned long long*>(address),
                   static_cast<unsigned long long>(expected),
                   static_cast<unsigned long long>(desired));
#else
  __atomic_compare_exchange_n(address, &expected, desired, false, __ATOMIC_ACQ_REL,
                              __ATOMIC_ACQUIRE);
  return expected;
#endif
}

COVOX_HD_INLINE uint32_t atomic_compare_exchange(uint32_t* address, uint32_t expected,
                                                 uint32_t desired) {
#if COVOX_DEVICE_CODE
  return atomicCAS(reinterpret_cast<unsigned int*>(address), expected, desired);
#else
  __atomic_compare_exchange_n(address, &expected, desired, false, __ATOMIC_ACQ_REL,
                              __ATOMIC_ACQUIRE);
  return expected;
#endif
}

// Returns the previous value.
COVOX_HD_INLINE uint32_t atomic_add(uint32_t* address, uint32_t value) {
#if COVOX_DEVICE_CODE
  return atomicAdd(reinterpret_cast<unsigned int*>(address), value);
#else
  return __atomic_fetch_add(address, value, __ATOMIC_RELAXED);
#endif
}

COVOX_HD_INLINE uint64_t atomic_add(uint64_t* address, uint64_t value) {
#if COVOX_DEVICE_CODE
  return atomicAdd(reinterpret_cast<unsigned long long*>(address),
                   static_cast<unsigned long long>(value));
#else
  return __atomic_fetch_add(address, value, __ATOMIC_RELAXED);
#endif
}

namespace internal {
// The host's atomic minimum / maximum: a CAS loop that stops once the stored value is no longer
// worse than `value`. Returns the previous value.
template <class T, class Better>
inline T host_atomic_extreme(T* address, T value, Better better) {
  T current = __atomic_load_n(address, __ATOMIC_RELAXED);
  while (better(value, current) &&
         !__atomic_compare_exchange_n(address, &current, value, true, __ATOMIC_ACQ_REL,
                                      __ATOMIC_RELAXED)) {
  }
  return current;
}
}  // namespace internal

// Atomic minimum / maximum; return the previous value.
COVOX_HD_INLINE uint32_t atomic_min(uint32_t* address, uint32_t value) {
#if COVOX_DEVICE_CODE
  return atomicMin(reinterpret_cast<unsigned int*>(address), value);
#else
  return internal::host_atomic_extreme(address, value,
                                       [](uint32_t a, uint32_t b) { return a < b; });
#endif
}
COVOX_HD_INLINE int32_t atomic_min(int32_t* address, int32_t value) {
#if COVOX_DEVICE_CODE
  return atomicMin(reinterpret_cast<int*>(address), value);
#else
  return internal::host_atomic_extreme(address, value, [](int32_t a, int32_t b) { return a < b; });
#endif
}
COVOX_HD_INLINE int32_t atomic_max(int32_t* address, int32_t value) {
#if COVOX_DEVICE_CODE
  return atomicMax(reinterpret_cast<int*>(address), value);
#else
  return internal::host_atomic_extreme(address, value, [](int32_t a, int32_t b) { return a > b; });
#endif
}

// Orders the calling thread's earlier writes and atomics before its later ones as every thread
// of the device sees them (a "last one out" hand-off: the GPU's __threadfence()).
COVOX_HD_INLINE void device_fence() {
#if COVOX_DEVICE_CODE
  __threadfence();
#else
  __atomic_thread_fence(__ATOMIC_SEQ_CST);
#endif
}

// A load that other threads' atomics may race with (relaxed on the host; on the GPU a plain
// load, which is enough where a stale value only sends the caller to a CAS that settles it).
COVOX_HD_INLINE uint64_t atomic_load_relaxed(const uint64_t* address) {
#if COVOX_DEVICE_CODE
  return *reinterpret_cast<const volatile uint64_t*>(address);
#else
  return __atomic_load_n(address, __ATOMIC_RELAXED);
#endif
}

// Sets a flag word to 1 unless it is set already. Many threads may mark the same flag in one
// kernel: each reads it first, on the GPU through its multiprocessor's L1 cache (a plain load: a
// stale 0 costs one more store of the same 1), so a hot flag is stored about once per
// multiprocessor, not once per thread. (Not a volatile load: that goes to L2 every time, and a
// traverse marks its hot flags from many threads.)
COVOX_HD_INLINE void mark_flag(uint32_t* flag) {
#if COVOX_DEVICE_CODE
  if (*flag == 0u) *flag = 1u;
#else
  if (__atomic_load_n(flag, __ATOMIC_RELAXED) == 0u) __atomic_store_n(flag, 1u, __ATOMIC_RELAXED);
#endif
}

}  // namespace covox

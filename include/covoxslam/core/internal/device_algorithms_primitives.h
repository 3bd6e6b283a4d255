#pragma once
// The per-backend primitive set behind device_algorithms.h: declared here, defined in
// device_algorithms_impl.h, explicitly instantiated once per backend.
#include <cstdint>

#include "covoxslam/core/stream.h"

namespace covox {
namespace algorithms {

template <class Backend>
struct Primitives {
  static void scale_add(const Stream& stream, float a, const float* x, float* y, int64_t count);
  static void exclusive_scan(const Stream& stream, const uint32_t* in, int64_t count,
                             uint32_t* out);
  static void scan_values_once(const Stream& stream, const uint32_t* in, int64_t count,
                               uint32_t* out, uint32_t* calls, bool through_functor);
  static void sort_by_key(const Stream& stream, uint64_t* keys, uint32_t* values, int64_t count);
  static void radix_sort_pairs(const Stream& stream, uint64_t* keys, uint32_t* values,
                               int64_t count, int key_bits, uint64_t* keys_alt,
                               uint32_t* values_alt);
  static int64_t reduce_by_key_sum(const Stream& stream, const uint64_t* keys, const float* values,
                                   int64_t count, uint64_t* keys_out, float* values_out);
  static void sum_runs_at_first(const Stream& stream, const uint64_t* keys, const double* values,
                                int64_t count, double* sums, uint32_t* calls,
                                const uint32_t* live_count);
  static int64_t unique(const Stream& stream, uint64_t* data, int64_t count);
  static double reduce_sum(const Stream& stream, const double* data, int64_t count);
  static void atomic_histogram(const Stream& stream, const uint32_t* bins, int64_t count,
                               uint32_t* histogram);
  static void atomic_claim_min(const Stream& stream, const uint32_t* targets, int64_t count,
                               uint32_t* owners);
};

}  // namespace algorithms
}  // namespace covox

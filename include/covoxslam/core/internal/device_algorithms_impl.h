#pragma once
// Template bodies behind device_algorithms.h (one per backend instantiation file).
#include <thrust/functional.h>

#include "covoxslam/core/atomics.h"
#include "covoxslam/core/internal/device_algorithms_primitives.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/radix_sort.h"
#include "covoxslam/core/run_sums.h"

namespace covox {
namespace algorithms {

template <class Backend>
void Primitives<Backend>::scale_add(const Stream& stream, float a, const float* x, float* y,
                                    int64_t count) {
  parallel_for(Backend{}, stream, count, [=] COVOX_HD(int64_t i) { y[i] = a * x[i] + y[i]; });
}
template <class Backend>
void Primitives<Backend>::exclusive_scan(const Stream& stream, const uint32_t* in, int64_t count,
                                         uint32_t* out) {
  covox::exclusive_scan(Backend{}, stream, in, count, out);
}
template <class Backend>
void Primitives<Backend>::sort_by_key(const Stream& stream, uint64_t* keys, uint32_t* values,
                                      int64_t count) {
  covox::sort_by_key(Backend{}, stream, keys, values, count);
}
template <class Backend>
void Primitives<Backend>::radix_sort_pairs(const Stream& stream, uint64_t* keys, uint32_t* values,
                                           int64_t count, int key_bits, uint64_t* keys_alt,
                                           uint32_t* values_alt) {
  covox::radix_sort_pairs(Backend{}, stream, keys, values, count, key_bits, keys_alt, values_alt);
}
template <class Backend>
int64_t Primitives<Backend>::reduce_by_key_sum(const Stream& stream, const uint64_t* keys,
                                               const float* values, int64_t count,
                                               uint64_t* keys_out, float* values_out) {
  return covox::reduce_by_key(Backend{}, stream, keys, values, count, keys_out, values_out,
                              thrust::plus<float>());
}
template <class Backend>
void Primitives<Backend>::sum_runs_at_first(const Stream& stream, const uint64_t* keys,
                                            const double* values, int64_t count, double* sums,
                                            uint32_t* calls, const uint32_t* live_count) {
  // Twice with one scratch buffer, as frames reuse theirs.
  Buffer<uint64_t> scratch(Backend::kDevice);
  for (int round = 0; round < 2; ++round) {
    consume_run_sums<double>(
        Backend{}, stream, keys, count, [=] COVOX_HD(int64_t j) { return values[j]; },
        thrust::plus<double>(),
        [=] COVOX_HD(int64_t first, double sum) {
          sums[first] = sum;
          atomic_add(calls + first, 1u);
        },
        scratch, nullptr, live_count);
  }
  stream.synchronize();  // the scratch goes out of scope
}
template <class Backend>
void Primitives<Backend>::scan_values_once(const Stream& stream, const uint32_t* in, int64_t count,
                                           uint32_t* out, uint32_t* calls, bool through_functor) {
  // one value per GPU thread (many small tiles, long look-backs); exclusive_scan tests the default
  const auto value_of = [=] COVOX_HD(int64_t i) -> uint32_t {
    atomic_add(calls + i, 1u);
    return in[i];
  };
  if (!through_functor) {
    exclusive_scan_of<1>(Backend{}, stream, count, value_of, out);
    return;
  }
  exclusive_scan_of<1>(Backend{}, stream, count, value_of,
                       [=] COVOX_HD(int64_t i, uint32_t prefix) {
                         out[i] = prefix;
                         atomic_add(calls + i, 1u << 16);
                       });
}
template <class Backend>
int64_t Primitives<Backend>::unique(const Stream& stream, uint64_t* data, int64_t count) {
  return covox::unique(Backend{}, stream, data, count);
}
template <class Backend>
double Primitives<Backend>::reduce_sum(const Stream& stream, const double* data, int64_t count) {
  return covox::reduce(Backend{}, stream, data, count, 0.0, thrust::plus<double>());
}
template <class Backend>
void Primitives<Backend>::atomic_histogram(const Stream& stream, const uint32_t* bins,
                                           int64_t count, uint32_t* histogram) {
  parallel_for(Backend{}, stream, count,
               [=] COVOX_HD(int64_t i) { atomic_add(&histogram[bins[i]], 1u); });
}
template <class Backend>
void Primitives<Backend>::atomic_claim_min(const Stream& stream, const uint32_t* targets,
                                           int64_t count, uint32_t* owners) {
  parallel_for(Backend{}, stream, count, [=] COVOX_HD(int64_t i) {
    uint32_t* owner = &owners[targets[i]];
    uint32_t current = *owner;
    const uint32_t mine = static_cast<uint32_t>(i);
    while (mine < current) {
      const uint32_t seen = atomic_compare_exchange(owner, current, mine);
      if (seen == current) break;
      current = seen;
    }
  });
}

}  // namespace algorithms
}  // namespace covox

#pragma once
// Runtime-dispatched entry points to the parallel primitives for the common element types, for
// code that is not itself templated on a backend (host-side orchestration, tests, tools). All
// pointers are memory of `device`. Each one runs the same template body on either backend.
#include <cstdint>

#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"

namespace covox {
namespace algorithms {

// y[i] = a * x[i] + y[i] (a parallel_for).
void scale_add(Device device, const Stream& stream, float a, const float* x, float* y,
               int64_t count);
// out[i] = sum of in[0..i).
void exclusive_scan(Device device, const Stream& stream, const uint32_t* in, int64_t count,
                    uint32_t* out);
// exclusive_scan_of (parallel.h, single_pass_scan.h) of value_of(i) = in[i], which also
// increments calls[i] (atomically): a test can check each value was read exactly once. With
// `through_functor` the prefixes go out through a functor (scan_output), which stores them and
// adds 2^16 to calls[i].
void scan_values_once(Device device, const Stream& stream, const uint32_t* in, int64_t count,
                      uint32_t* out, uint32_t* calls, bool through_functor = false);
// Stable sort of keys, values permuted along.
void sort_by_key(Device device, const Stream& stream, uint64_t* keys, uint32_t* values,
                 int64_t count);
// Stable sort by the low key_bits bits of the keys (see radix_sort.h); *_alt are scratch arrays
// of `count` elements.
void radix_sort_pairs(Device device, const Stream& stream, uint64_t* keys, uint32_t* values,
                      int64_t count, int key_bits, uint64_t* keys_alt, uint32_t* values_alt);
// Sums each run of equal consecutive keys; returns the number of runs.
int64_t reduce_by_key_sum(Device device, const Stream& stream, const uint64_t* keys,
                          const float* values, int64_t count, uint64_t* keys_out,
                          float* values_out);
// consume_run_sums (run_sums.h) over sorted keys with double terms, twice with one scratch
// buffer: each run's sum is written at sums[first record of the run] and calls[that record] is
// incremented (atomically), so a test can check every run was handed over exactly once per call
// (calls == 2) with the right sum; other entries are untouched. With `live_count` (memory of the
// device), only the first *live_count records count.
void sum_runs_at_first(Device device, const Stream& stream, const uint64_t* keys,
                       const double* values, int64_t count, double* sums, uint32_t* calls,
                       const uint32_t* live_count = nullptr);
// Removes consecutive duplicates in place; returns the new count.
int64_t unique(Device device, const Stream& stream, uint64_t* data, int64_t count);
double reduce_sum(Device device, const Stream& stream, const double* data, int64_t count);
// histogram[bins[i]] += 1 for every i, with atomic_add from many threads at once.
void atomic_histogram(Device device, const Stream& stream, const uint32_t* bins, int64_t count,
                      uint32_t* histogram);
// For every i, CAS-claims owners[targets[i]] (initially 0xffffffff) with i if it is smaller than
// the current owner, so afterwards owners[t] == min{i : targets[i] == t}. Exercises
// atomic_compare_exchange under contention.
void atomic_claim_min(Device device, const Stream& stream, const uint32_t* targets, int64_t count,
                      uint32_t* owners);

}  // namespace algorithms
}  // namespace covox

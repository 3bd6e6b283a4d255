#include "covoxslam/core/device_algorithms.h"
#include "covoxslam/core/internal/device_algorithms_primitives.h"

#include <cstdint>

namespace covox {
namespace algorithms {

#define COVOX_DISPATCH_PRIMITIVE(call) \
  dispatch(device, [&](auto backend) { return Primitives<decltype(backend)>::call; })

void scale_add(Device device, const Stream& stream, float a, const float* x, float* y,
               int64_t count) {
  COVOX_DISPATCH_PRIMITIVE(scale_add(stream, a, x, y, count));
}
void exclusive_scan(Device device, const Stream& stream, const uint32_t* in, int64_t count,
                    uint32_t* out) {
  COVOX_DISPATCH_PRIMITIVE(exclusive_scan(stream, in, count, out));
}
void scan_values_once(Device device, const Stream& stream, const uint32_t* in, int64_t count,
                      uint32_t* out, uint32_t* calls, bool through_functor) {
  COVOX_DISPATCH_PRIMITIVE(scan_values_once(stream, in, count, out, calls, through_functor));
}
void sort_by_key(Device device, const Stream& stream, uint64_t* keys, uint32_t* values,
                 int64_t count) {
  COVOX_DISPATCH_PRIMITIVE(sort_by_key(stream, keys, values, count));
}
void radix_sort_pairs(Device device, const Stream& stream, uint64_t* keys, uint32_t* values,
                      int64_t count, int key_bits, uint64_t* keys_alt, uint32_t* values_alt) {
  COVOX_DISPATCH_PRIMITIVE(
      radix_sort_pairs(stream, keys, values, count, key_bits, keys_alt, values_alt));
}
int64_t reduce_by_key_sum(Device device, const Stream& stream, const uint64_t* keys,
                          const float* values, int64_t count, uint64_t* keys_out,
                          float* values_out) {
  return COVOX_DISPATCH_PRIMITIVE(
      reduce_by_key_sum(stream, keys, values, count, keys_out, values_out));
}
int64_t unique(Device device, const Stream& stream, uint64_t* data, int64_t count) {
  return COVOX_DISPATCH_PRIMITIVE(unique(stream, data, count));
}
double reduce_sum(Device device, const Stream& stream, const double* data, int64_t count) {
  return COVOX_DISPATCH_PRIMITIVE(reduce_sum(stream, data, count));
}
void atomic_histogram(Device device, const Stream& stream, const uint32_t* bins, int64_t count,
                      uint32_t* histogram) {
  COVOX_DISPATCH_PRIMITIVE(atomic_histogram(stream, bins, count, histogram));
}
void sum_runs_at_first(Device device, const Stream& stream, const uint64_t* keys,
                       const double* values, int64_t count, double* sums, uint32_t* calls,
                       const uint32_t* live_count) {
  COVOX_DISPATCH_PRIMITIVE(sum_runs_at_first(stream, keys, values, count, sums, calls, live_count));
}
void atomic_claim_min(Device device, const Stream& stream, const uint32_t* targets, int64_t count,
                      uint32_t* owners) {
  COVOX_DISPATCH_PRIMITIVE(atomic_claim_min(stream, targets, count, owners));
}

}  // namespace algorithms
}  // namespace covox

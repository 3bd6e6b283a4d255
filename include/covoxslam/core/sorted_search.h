#pragma once
// Binary search in a sorted array, callable from kernels of both backends.
#include <cstdint>

#include "covoxslam/core/macros.h"

namespace covox {

// First index in the ascending data[0, count) whose element is >= `value` (count if none).
template <class T>
COVOX_HD_INLINE int64_t lower_bound_index(const T* data, int64_t count, const T& value) {
  int64_t low = 0, high = count;
  while (low < high) {
    const int64_t middle = low + (high - low) / 2;
    if (data[middle] < value)
      low = middle + 1;
    else
      high = middle;
  }
  return low;
}

}  // namespace covox

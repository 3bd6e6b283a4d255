#pragma once
// The number of set bits of a 32-bit word, on either backend.
#include <cstdint>

#include "covoxslam/core/macros.h"

namespace covox {

COVOX_HD_INLINE uint32_t count_bits(uint32_t word) {
#if COVOX_DEVICE_CODE
  return static_cast<uint32_t>(__popc(word));
#else
  return static_cast<uint32_t>(__builtin_popcount(word));
#endif
}

}  // namespace covox

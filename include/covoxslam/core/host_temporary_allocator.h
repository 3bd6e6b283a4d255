#pragma once
// Host memory for TemporaryCache (temporary_cache.h): the CPU backend's Thrust scratch.
#include <cstdlib>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/core/temporary_cache.h"

namespace covox {

struct HostRawMemory {
  static char* allocate(size_t bytes) { return static_cast<char*>(std::malloc(bytes)); }
  static void release(char* pointer) { std::free(pointer); }
  static void synchronize_all() {}  // host work is finished when the primitive returns
  [[noreturn]] static void fail(size_t bytes) {
    throw OutOfMemoryError("out of host memory: " + std::to_string(bytes) +
                           " bytes of temporary storage for a parallel primitive");
  }
};

using HostTemporaryAllocator = TemporaryAllocator<HostRawMemory>;

}  // namespace covox

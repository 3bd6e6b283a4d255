#pragma once
// GPU memory for TemporaryCache (temporary_cache.h): the CUDA backend's Thrust scratch. Without
// the cache every sort, scan or reduce_by_key would call cudaMalloc and cudaFree, which cost tens
// of microseconds each and synchronise the device.
#include <cuda_runtime.h>

#include <cstddef>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/core/temporary_cache.h"

namespace covox {

struct CudaRawMemory {
  static char* allocate(size_t bytes) {
    void* pointer = nullptr;
    if (cudaMalloc(&pointer, bytes) != cudaSuccess) {
      cudaGetLastError();  // clear the error: the cache frees its blocks and tries again
      return nullptr;
    }
    return static_cast<char*>(pointer);
  }
  static void release(char* pointer) { cudaFree(pointer); }
  static void synchronize_all() { cudaDeviceSynchronize(); }
  [[noreturn]] static void fail(size_t bytes) {
    throw OutOfMemoryError("out of GPU memory: " + std::to_string(bytes) +
                           " bytes of temporary storage for a parallel primitive");
  }
};

using CudaTemporaryAllocator = TemporaryAllocator<CudaRawMemory>;

}  // namespace covox

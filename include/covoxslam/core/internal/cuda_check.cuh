#pragma once
// CUDA error checking for .cu files (never included by host-only code).
#include <cuda_runtime.h>

#include <string>

#include "covoxslam/core/error.h"

namespace covox {

inline void cuda_check(cudaError_t status, const char* what) {
  if (status == cudaSuccess) return;
  const std::string message = std::string("CUDA error during ") + what + ": " +
                              cudaGetErrorName(status) + " (" + cudaGetErrorString(status) + ")";
  if (status == cudaErrorMemoryAllocation) throw OutOfMemoryError(message);
  throw Error(message);
}

}  // namespace covox

#pragma once
// A caching allocator for Thrust's temporary storage on the GPU. Without it every sort, scan or
// reduce_by_key calls cudaMalloc and cudaFree, which cost tens of microseconds each and
// synchronise the device: more than a whole TSDF frame is allowed to take.
//
// Freed blocks are kept per stream and handed out again (smallest block that fits). Reuse is
// safe because work on one stream runs in order: a later algorithm on the same stream cannot
// start before the earlier one that used the block has finished. Blocks are never shared
// between streams.
#include <cuda_runtime.h>

#include <cstddef>
#include <map>
#include <mutex>
#include <unordered_map>

#include "covoxslam/core/cuda_check.cuh"

namespace covox {

class CudaTemporaryCache {
 public:
  static CudaTemporaryCache& instance() {
    static CudaTemporaryCache* cache = new CudaTemporaryCache();  // never destroyed: outlives static buffers
    return *cache;
  }

  char* allocate(cudaStream_t stream, std::ptrdiff_t bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto& free_blocks = free_[stream];
    auto fit = free_blocks.lower_bound(static_cast<size_t>(bytes));
    if (fit != free_blocks.end()) {
      char* pointer = fit->second;
      live_[pointer] = {stream, fit->first};
      free_blocks.erase(fit);
      return pointer;
    }
    void* pointer = nullptr;
    cudaError_t status = cudaMalloc(&pointer, static_cast<size_t>(bytes));
    if (status != cudaSuccess) {
      // Give cached memory back and try once more before failing.
      cudaGetLastError();
      release_free_blocks_locked();
      status = cudaMalloc(&pointer, static_cast<size_t>(bytes));
    }
    cuda_check(status, "temporary allocation for a parallel primitive");
    live_[static_cast<char*>(pointer)] = {stream, static_cast<size_t>(bytes)};
    return static_cast<char*>(pointer);
  }

  void deallocate(char* pointer) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = live_.find(pointer);
    if (it == live_.end()) return;
    free_[it->second.stream].emplace(it->second.bytes, pointer);
    live_.erase(it);
  }

 private:
  struct LiveBlock {
    cudaStream_t stream;
    size_t bytes;
  };
  void release_free_blocks_locked() {
    cudaDeviceSynchronize();
    for (auto& [stream, blocks] : free_) {
      for (auto& [bytes, pointer] : blocks) cudaFree(pointer);
      blocks.clear();
    }
  }

  std::mutex mutex_;
  std::unordered_map<cudaStream_t, std::multimap<size_t, char*>> free_;
  std::unordered_map<char*, LiveBlock> live_;
};

// The allocator interface Thrust expects (value_type, allocate, deallocate).
struct CudaTemporaryAllocator {
  using value_type = char;
  cudaStream_t stream = nullptr;
  char* allocate(std::ptrdiff_t bytes) { return CudaTemporaryCache::instance().allocate(stream, bytes); }
  void deallocate(char* pointer, size_t) { CudaTemporaryCache::instance().deallocate(pointer); }
};

}  // namespace covox

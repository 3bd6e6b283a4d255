#pragma once
// A caching allocator for the temporary storage of the parallel primitives (Thrust's sort, scan,
// reduce_by_key). Without it every call allocates and frees its scratch: on the GPU cudaMalloc
// and cudaFree are slow next to a frame's kernels and synchronise the device; on the CPU a large
// malloc is a fresh mmap whose pages fault in again on every frame.
//
// Freed blocks are kept per stream and handed out again (the smallest block that fits). Reuse is
// safe because work on one stream runs in order: a later algorithm on the same stream cannot
// start before the earlier one that used the block has finished. Blocks are never shared between
// streams. `RawMemory` supplies allocate(bytes) (nullptr on failure), release(pointer) and
// synchronize_all() for one kind of memory.
#include <cstddef>
#include <map>
#include <mutex>
#include <unordered_map>

namespace covox {

template <class RawMemory>
class TemporaryCache {
 public:
  static TemporaryCache& instance() {
    static TemporaryCache* cache =
        new TemporaryCache();  // never destroyed: outlives static buffers
    return *cache;
  }

  // Throws what RawMemory::fail throws when even an emptied cache cannot satisfy the request.
  char* allocate(const void* stream, std::ptrdiff_t bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto& free_blocks = free_[stream];
    auto fit = free_blocks.lower_bound(static_cast<size_t>(bytes));
    if (fit != free_blocks.end()) {
      char* pointer = fit->second;
      live_[pointer] = {stream, fit->first};
      free_blocks.erase(fit);
      return pointer;
    }
    char* pointer = RawMemory::allocate(static_cast<size_t>(bytes));
    if (!pointer) {
      // Give cached memory back and try once more before failing.
      release_free_blocks_locked();
      pointer = RawMemory::allocate(static_cast<size_t>(bytes));
      if (!pointer) RawMemory::fail(static_cast<size_t>(bytes));
    }
    live_[pointer] = {stream, static_cast<size_t>(bytes)};
    return pointer;
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
    const void* stream;
    size_t bytes;
  };
  void release_free_blocks_locked() {
    RawMemory::synchronize_all();
    for (auto& [stream, blocks] : free_) {
      for (auto& [bytes, pointer] : blocks) RawMemory::release(pointer);
      blocks.clear();
    }
  }

  std::mutex mutex_;
  std::unordered_map<const void*, std::multimap<size_t, char*>> free_;
  std::unordered_map<char*, LiveBlock> live_;
};

// The allocator interface Thrust expects (value_type, allocate, deallocate), for one stream.
template <class RawMemory>
struct TemporaryAllocator {
  using value_type = char;
  const void* stream = nullptr;
  char* allocate(std::ptrdiff_t bytes) {
    return TemporaryCache<RawMemory>::instance().allocate(stream, bytes);
  }
  void deallocate(char* pointer, size_t) {
    TemporaryCache<RawMemory>::instance().deallocate(pointer);
  }
};

}  // namespace covox

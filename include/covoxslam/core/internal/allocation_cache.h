#pragma once
// AllocationCache: freed GPU allocations kept for reuse instead of handed back to the driver
// (cudaMalloc and cudaFree cost far more than the kernels around them when a submap's pools come
// and go, and cudaFree waits for the whole device). It keeps freed blocks up to max_cached_bytes
// and hands one out for a request that uses at least 3/4 of it. Reuse is safe across streams: a
// block freed while kernels may still use it is handed out again only after a device-wide
// synchronisation that came after its free, which is what cudaFree would have done. A backend
// allocation that fails is retried once after the cache is flushed. The backend is injected so
// that the policy is tested on the host.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <unordered_map>

namespace covox {
namespace internal {

class AllocationCache {
 public:
  struct Backend {
    std::function<void*(size_t)> allocate;  // nullptr on failure
    std::function<void(void*)> release;
    std::function<void()> synchronize;  // waits until no queued work can touch freed memory
  };
  AllocationCache(Backend backend, size_t max_cached_bytes);
  AllocationCache(const AllocationCache&) = delete;
  AllocationCache& operator=(const AllocationCache&) = delete;

  // A block of at least `bytes` (> 0), cached or new; nullptr when the backend fails even after
  // the cache was flushed.
  void* allocate(size_t bytes);
  // Takes back a block from allocate(): cached, the least recently freed released beyond the
  // limit (a block larger than the limit, or one allocate() did not hand out, is released at
  // once).
  void free(void* pointer);
  // Synchronises and releases every cached block.
  void flush();
  // Keeps at most `max_cached_bytes` from now on, releasing the least recently freed beyond it.
  void set_limit(size_t max_cached_bytes);
  size_t cached_bytes() const;

  // Reuse keeps waste under a quarter of the block: request * kMaxWasteDivisor >= block *
  // (kMaxWasteDivisor - 1).
  static constexpr size_t kMaxWasteDivisor = 4;

 private:
  struct Cached {
    void* pointer;
    uint64_t freed_at;  // free_clock_ at its free
  };
  void flush_locked();
  void release_oldest_locked();

  Backend backend_;
  size_t max_cached_bytes_;
  mutable std::mutex mutex_;
  using CachedBySize = std::multimap<size_t, Cached>;
  std::unordered_map<void*, size_t> capacity_;                // every block handed out or cached
  CachedBySize cached_;                                       // by capacity
  std::map<uint64_t, CachedBySize::iterator> cached_by_age_;  // the same blocks by freed_at
  size_t cached_bytes_ = 0;
  uint64_t free_clock_ = 0;
  uint64_t synchronised_through_ = 0;  // blocks freed at or before this clock are safe to reuse
};

}  // namespace internal
}  // namespace covox

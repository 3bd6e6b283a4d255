#include "covoxslam/core/internal/allocation_cache.h"

#include <utility>

namespace covox {
namespace internal {

AllocationCache::AllocationCache(Backend backend, size_t max_cached_bytes)
    : backend_(std::move(backend)), max_cached_bytes_(max_cached_bytes) {}

void* AllocationCache::allocate(size_t bytes) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto fit = cached_.lower_bound(bytes);
  if (fit != cached_.end() && bytes * kMaxWasteDivisor >= fit->first * (kMaxWasteDivisor - 1)) {
    if (fit->second.freed_at > synchronised_through_) {
      backend_.synchronize();
      synchronised_through_ = free_clock_;
    }
    void* pointer = fit->second.pointer;
    cached_bytes_ -= fit->first;
    cached_by_age_.erase(fit->second.freed_at);
    cached_.erase(fit);
    return pointer;
  }
  void* pointer = backend_.allocate(bytes);
  if (!pointer && !cached_.empty()) {
    flush_locked();
    pointer = backend_.allocate(bytes);
  }
  if (pointer) capacity_[pointer] = bytes;
  return pointer;
}

void AllocationCache::free(void* pointer) {
  if (!pointer) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = capacity_.find(pointer);
  if (it == capacity_.end()) {  // not from allocate(): nothing to keep
    backend_.release(pointer);
    return;
  }
  const size_t capacity = it->second;
  if (capacity > max_cached_bytes_) {
    capacity_.erase(it);
    backend_.release(pointer);
    return;
  }
  const uint64_t freed_at = ++free_clock_;
  cached_by_age_.emplace(freed_at, cached_.emplace(capacity, Cached{pointer, freed_at}));
  cached_bytes_ += capacity;
  while (cached_bytes_ > max_cached_bytes_) release_oldest_locked();
}

void AllocationCache::flush() {
  std::lock_guard<std::mutex> lock(mutex_);
  flush_locked();
}

void AllocationCache::set_limit(size_t max_cached_bytes) {
  std::lock_guard<std::mutex> lock(mutex_);
  max_cached_bytes_ = max_cached_bytes;
  while (cached_bytes_ > max_cached_bytes_) release_oldest_locked();
}

size_t AllocationCache::cached_bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return cached_bytes_;
}

void AllocationCache::flush_locked() {
  if (cached_.empty()) return;
  backend_.synchronize();
  synchronised_through_ = free_clock_;
  while (!cached_.empty()) release_oldest_locked();
}

void AllocationCache::release_oldest_locked() {
  const CachedBySize::iterator oldest = cached_by_age_.begin()->second;
  cached_by_age_.erase(cached_by_age_.begin());
  void* pointer = oldest->second.pointer;
  cached_bytes_ -= oldest->first;
  cached_.erase(oldest);
  capacity_.erase(pointer);
  backend_.release(pointer);
}

}  // namespace internal
}  // namespace covox

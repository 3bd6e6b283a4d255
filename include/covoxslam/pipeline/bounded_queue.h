#pragma once
// BoundedQueue: the hand-over between the SLAM threads (sensor input to front end, front end to
// back end).
//
// Live input: the producer never waits; when the queue is full, push() drops the OLDEST entry
// and counts it. Dropping the oldest (not the newest) keeps the map following the robot: after a
// stall the frontend resumes with the most recent scans instead of catching up on stale ones.
// Offline input: push_waiting() waits for room instead, so nothing is lost and what is mapped does
// not depend on the machine's speed.
// Consumers block in pop() until an entry arrives, the queue is closed and drained, or aborted.
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <utility>

#include "covoxslam/core/error.h"

namespace covox {
namespace pipeline {

enum class PushResult {
  kQueued,               // accepted, nothing lost
  kQueuedDroppedOldest,  // accepted; the oldest entry was dropped to make room
  kRejectedClosed,       // the queue no longer accepts entries (finish() or shutdown)
};

enum class PopResult {
  kItem,      // an entry was taken
  kWoken,     // wake() was called: the consumer has other work (no entry taken)
  kFinished,  // closed and drained, or aborted
};

template <class T>
class BoundedQueue {
 public:
  using Clock = std::chrono::steady_clock;

  // `what` names the queue in error messages ("sensor queue", "submap queue").
  BoundedQueue(size_t capacity, std::string what) : capacity_(capacity), what_(std::move(what)) {
    if (capacity_ == 0) throw Error(what_ + ": the capacity must be at least 1 entry");
  }
  BoundedQueue(const BoundedQueue&) = delete;
  BoundedQueue& operator=(const BoundedQueue&) = delete;

  // Appends `item`. When full, the oldest entry is removed and handed to `dropped` (if given) so
  // the caller can account for it; otherwise it is destroyed after the lock is released (a
  // submap's voxel memory is freed without blocking the other thread).
  PushResult push(T item, std::optional<T>* dropped = nullptr) {
    std::optional<T> victim;
    PushResult result = PushResult::kQueued;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (closed_ || aborted_) return PushResult::kRejectedClosed;
      if (entries_.size() >= capacity_) {
        victim.emplace(std::move(entries_.front().item));
        entries_.pop_front();
        ++dropped_count_;
        result = PushResult::kQueuedDroppedOldest;
      }
      entries_.push_back(Entry{std::move(item), Clock::now()});
      ++pushed_count_;
    }
    ready_.notify_one();
    if (dropped) *dropped = std::move(victim);
    return result;
  }

  // Appends `item` once the queue has room, waiting for a consumer to take an entry (or for
  // clear()); kRejectedClosed when the queue is (or gets) closed or aborted meanwhile.
  PushResult push_waiting(T item) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      room_.wait(lock, [this] { return closed_ || aborted_ || entries_.size() < capacity_; });
      if (closed_ || aborted_) return PushResult::kRejectedClosed;
      entries_.push_back(Entry{std::move(item), Clock::now()});
      ++pushed_count_;
    }
    ready_.notify_one();
    return PushResult::kQueued;
  }

  // Waits for the next entry. Returns false when the queue is closed and empty, or aborted.
  // `waited_s` (optional) receives how long the entry sat in the queue (the "queue wait").
  bool pop(T* item, double* waited_s = nullptr) {
    std::unique_lock<std::mutex> lock(mutex_);
    ready_.wait(lock, [this] { return aborted_ || closed_ || !entries_.empty(); });
    if (aborted_ || entries_.empty()) return false;
    Entry entry = std::move(entries_.front());
    entries_.pop_front();
    lock.unlock();
    room_.notify_one();
    if (waited_s) *waited_s = std::chrono::duration<double>(Clock::now() - entry.queued_at).count();
    *item = std::move(entry.item);
    return true;
  }

  // Like pop(), but also returns kWoken (once per wake() call, or per burst of them) so that a
  // consumer that waits for entries can also be told about other work (the SLAM backend: loop
  // closures or an optimisation request arriving while no submap is queued). Queued entries come
  // first: a wake-up is reported when none is waiting.
  PopResult pop_or_wake(T* item, double* waited_s = nullptr) {
    std::unique_lock<std::mutex> lock(mutex_);
    ready_.wait(lock, [this] { return aborted_ || closed_ || woken_ || !entries_.empty(); });
    if (aborted_) return PopResult::kFinished;
    if (entries_.empty()) {
      if (woken_) {
        woken_ = false;
        return PopResult::kWoken;
      }
      return PopResult::kFinished;  // closed and drained
    }
    Entry entry = std::move(entries_.front());
    entries_.pop_front();
    lock.unlock();
    room_.notify_one();
    if (waited_s) *waited_s = std::chrono::duration<double>(Clock::now() - entry.queued_at).count();
    *item = std::move(entry.item);
    return PopResult::kItem;
  }

  // Makes a waiting (or the next) pop_or_wake() return kWoken if no entry is queued.
  void wake() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      woken_ = true;
    }
    ready_.notify_all();
  }

  // Discards every queued entry but keeps accepting (SlamSystem::reset). Returns how many.
  size_t clear() {
    std::deque<Entry> discarded;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      discarded.swap(entries_);
    }
    room_.notify_all();
    return discarded.size();  // destroyed here, outside the lock
  }

  // No more pushes; pop() still hands out what is queued, then returns false (a flush).
  void close() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
    room_.notify_all();
  }

  // Accepts pushes again after close() (SlamSystem::resume); an aborted queue stays aborted.
  void reopen() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!aborted_) closed_ = false;
  }

  // No more pushes and pop() returns false at once; queued entries are discarded (shutdown).
  // Returns how many were discarded, so the caller can count them.
  size_t abort() {
    std::deque<Entry> discarded;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      aborted_ = true;
      closed_ = true;
      discarded.swap(entries_);
    }
    ready_.notify_all();
    room_.notify_all();
    return discarded.size();
  }

  size_t capacity() const { return capacity_; }
  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return entries_.size();
  }
  int64_t dropped_count() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_count_;
  }
  int64_t pushed_count() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return pushed_count_;
  }

 private:
  struct Entry {
    T item;
    Clock::time_point queued_at;
  };
  const size_t capacity_;
  const std::string what_;
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::condition_variable room_;  // push_waiting(): an entry was taken, or the queue closed
  std::deque<Entry> entries_;
  bool closed_ = false;
  bool aborted_ = false;
  bool woken_ = false;
  int64_t dropped_count_ = 0;
  int64_t pushed_count_ = 0;
};

}  // namespace pipeline
}  // namespace covox

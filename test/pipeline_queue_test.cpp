// BoundedQueue: the hand-over between the SLAM threads drops its OLDEST entry when full and counts
// it, drains on close(), discards on abort(), and never leaves a consumer waiting forever.
#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <optional>
#include <thread>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/bounded_queue.h"

namespace covox {
namespace pipeline {
namespace {

TEST(PipelineQueue, FullQueueDropsTheOldestEntryAndCountsIt) {
  BoundedQueue<int> queue(3, "test queue");
  std::vector<PushResult> results;
  std::vector<int> dropped_values;
  for (int value = 1; value <= 5; ++value) {
    std::optional<int> dropped;
    results.push_back(queue.push(value, &dropped));
    if (dropped) dropped_values.push_back(*dropped);
  }
  EXPECT_EQ(results[0], PushResult::kQueued);
  EXPECT_EQ(results[2], PushResult::kQueued);
  EXPECT_EQ(results[3], PushResult::kQueuedDroppedOldest);
  EXPECT_EQ(results[4], PushResult::kQueuedDroppedOldest);
  EXPECT_EQ(dropped_values, (std::vector<int>{1, 2}));
  EXPECT_EQ(queue.dropped_count(), 2);
  EXPECT_EQ(queue.pushed_count(), 5);
  EXPECT_EQ(queue.size(), 3u);

  queue.close();
  std::vector<int> popped;
  int value = 0;
  double waited_s = -1.0;
  while (queue.pop(&value, &waited_s)) {
    popped.push_back(value);
    EXPECT_GE(waited_s, 0.0);
  }
  // The newest entries survive, in order.
  EXPECT_EQ(popped, (std::vector<int>{3, 4, 5}));
}

TEST(PipelineQueue, ClosedQueueRejectsPushesButDrainsWhatItHolds) {
  BoundedQueue<int> queue(4, "test queue");
  queue.push(7);
  queue.close();
  EXPECT_EQ(queue.push(8), PushResult::kRejectedClosed);
  int value = 0;
  ASSERT_TRUE(queue.pop(&value));
  EXPECT_EQ(value, 7);
  EXPECT_FALSE(queue.pop(&value));
}

TEST(PipelineQueue, AbortDiscardsEntriesAndReportsHowMany) {
  BoundedQueue<int> queue(4, "test queue");
  queue.push(1);
  queue.push(2);
  EXPECT_EQ(queue.abort(), 2u);
  int value = 0;
  EXPECT_FALSE(queue.pop(&value));
  EXPECT_EQ(queue.push(3), PushResult::kRejectedClosed);
}

TEST(PipelineQueue, BlockedConsumerWakesOnPushAndOnClose) {
  BoundedQueue<int> queue(2, "test queue");
  auto consumer = std::async(std::launch::async, [&queue] {
    std::vector<int> seen;
    int value = 0;
    while (queue.pop(&value)) seen.push_back(value);
    return seen;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  queue.push(42);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  queue.close();
  ASSERT_EQ(consumer.wait_for(std::chrono::seconds(5)), std::future_status::ready)
      << "consumer did not wake up";
  EXPECT_EQ(consumer.get(), (std::vector<int>{42}));
}

TEST(PipelineQueue, WakeReachesAWaitingConsumerButEntriesComeFirst) {
  BoundedQueue<int> queue(4, "test queue");
  // A consumer blocked in pop_or_wake() returns kWoken without an entry.
  auto woken = std::async(std::launch::async, [&queue] {
    int value = 0;
    return queue.pop_or_wake(&value);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  queue.wake();
  ASSERT_EQ(woken.wait_for(std::chrono::seconds(5)), std::future_status::ready)
      << "consumer did not wake up";
  EXPECT_EQ(woken.get(), PopResult::kWoken);
  // Queued entries are handed out before a pending wake-up, which is reported once.
  queue.push(1);
  queue.wake();
  queue.wake();
  int value = 0;
  EXPECT_EQ(queue.pop_or_wake(&value), PopResult::kItem);
  EXPECT_EQ(value, 1);
  EXPECT_EQ(queue.pop_or_wake(&value), PopResult::kWoken);
  queue.close();
  EXPECT_EQ(queue.pop_or_wake(&value), PopResult::kFinished);
}

TEST(PipelineQueue, ClearDiscardsEntriesButKeepsAccepting) {
  BoundedQueue<int> queue(4, "test queue");
  queue.push(1);
  queue.push(2);
  EXPECT_EQ(queue.clear(), 2u);
  EXPECT_EQ(queue.size(), 0u);
  EXPECT_EQ(queue.push(3), PushResult::kQueued);
  queue.close();
  int value = 0;
  ASSERT_TRUE(queue.pop(&value));
  EXPECT_EQ(value, 3);
  EXPECT_FALSE(queue.pop(&value));
}

TEST(PipelineQueue, WaitingProducerLosesNothingAndStopsOnClose) {
  BoundedQueue<int> queue(1, "test queue");
  auto producer = std::async(std::launch::async, [&queue] {
    std::vector<PushResult> results;
    for (int value = 0; value < 50; ++value) results.push_back(queue.push_waiting(value));
    return results;
  });
  std::vector<int> seen;
  int value = 0;
  while (seen.size() < 50 && queue.pop(&value)) {
    seen.push_back(value);
    if (seen.size() % 10 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_EQ(producer.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  for (const PushResult result : producer.get()) EXPECT_EQ(result, PushResult::kQueued);
  std::vector<int> expected(50);
  for (int i = 0; i < 50; ++i) expected[i] = i;
  EXPECT_EQ(seen, expected);
  EXPECT_EQ(queue.dropped_count(), 0);

  // A producer waiting on a full queue is released by close(), its entry refused.
  queue.push_waiting(1);
  auto blocked = std::async(std::launch::async, [&queue] { return queue.push_waiting(2); });
  EXPECT_EQ(blocked.wait_for(std::chrono::milliseconds(50)), std::future_status::timeout);
  queue.close();
  ASSERT_EQ(blocked.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  EXPECT_EQ(blocked.get(), PushResult::kRejectedClosed);
}

TEST(PipelineQueue, ZeroCapacityIsAClearError) {
  try {
    BoundedQueue<int> queue(0, "sensor queue");
    FAIL() << "expected covox::Error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("sensor queue"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

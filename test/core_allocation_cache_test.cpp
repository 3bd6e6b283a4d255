// The device allocation cache's policy (core/internal/allocation_cache.h) against a host backend
// that records what the driver would have been asked to do.
#include <gtest/gtest.h>

#include <cstdlib>
#include <set>
#include <vector>

#include "covoxslam/core/internal/allocation_cache.h"

namespace covox {
namespace internal {
namespace {

struct RecordingDriver {
  std::set<void*> live;  // allocated by the driver and not released
  int allocations = 0, releases = 0, synchronisations = 0;
  bool fail_next = false;

  AllocationCache::Backend backend() {
    return AllocationCache::Backend{[this](size_t bytes) -> void* {
                                      if (fail_next) {
                                        fail_next = false;
                                        return nullptr;
                                      }
                                      ++allocations;
                                      void* pointer = std::malloc(bytes);
                                      live.insert(pointer);
                                      return pointer;
                                    },
                                    [this](void* pointer) {
                                      ++releases;
                                      live.erase(pointer);
                                      std::free(pointer);
                                    },
                                    [this] { ++synchronisations; }};
  }
};

TEST(AllocationCache, AFreedBlockComesBackForARequestItFitsAfterOneSynchronisation) {
  RecordingDriver driver;
  {
    AllocationCache cache(driver.backend(), 1 << 20);
    void* a = cache.allocate(1000);
    void* b = cache.allocate(4000);
    cache.free(a);
    cache.free(b);
    EXPECT_EQ(cache.cached_bytes(), 5000u);
    // 900 fits the 1000-byte block (waste under a quarter); both frees came after the last
    // synchronisation, so the first reuse synchronises once and the second needs none.
    EXPECT_EQ(cache.allocate(900), a);
    EXPECT_EQ(cache.allocate(3500), b);
    EXPECT_EQ(driver.allocations, 2);
    EXPECT_EQ(driver.synchronisations, 1);
    // A block freed after that synchronisation needs another before it is handed out again.
    cache.free(a);
    EXPECT_EQ(cache.allocate(1000), a);
    EXPECT_EQ(driver.synchronisations, 2);
    cache.free(a);
    cache.free(b);
    cache.flush();
    EXPECT_EQ(cache.cached_bytes(), 0u);
    EXPECT_TRUE(driver.live.empty());
  }
  EXPECT_EQ(driver.releases, 2);
}

TEST(AllocationCache, ABlockFarLargerThanTheRequestIsNotReused) {
  RecordingDriver driver;
  AllocationCache cache(driver.backend(), 1 << 20);
  void* big = cache.allocate(4000);
  cache.free(big);
  void* small = cache.allocate(2999);  // under 3/4 of 4000: a new block
  EXPECT_NE(small, big);
  EXPECT_EQ(driver.allocations, 2);
  EXPECT_EQ(driver.synchronisations, 0);
  void* fits = cache.allocate(3000);  // exactly 3/4: reused
  EXPECT_EQ(fits, big);
  cache.free(small);
  cache.free(fits);
  cache.flush();
  EXPECT_TRUE(driver.live.empty());
}

TEST(AllocationCache, TheLimitReleasesTheLeastRecentlyFreedAndLargeBlocksAtOnce) {
  RecordingDriver driver;
  AllocationCache cache(driver.backend(), 10000);
  std::vector<void*> blocks;
  for (int k = 0; k < 4; ++k) blocks.push_back(cache.allocate(3000));
  void* huge = cache.allocate(20000);
  cache.free(huge);  // over the limit on its own: straight back to the driver
  EXPECT_EQ(driver.releases, 1);
  EXPECT_EQ(driver.live.count(huge), 0u);
  for (void* block : blocks) cache.free(block);
  // 12000 bytes freed into a 10000-byte cache: the first freed went back to the driver.
  EXPECT_EQ(cache.cached_bytes(), 9000u);
  EXPECT_EQ(driver.live.count(blocks[0]), 0u);
  for (int k = 1; k < 4; ++k) EXPECT_EQ(driver.live.count(blocks[k]), 1u);
  cache.flush();
  EXPECT_TRUE(driver.live.empty());
}

TEST(AllocationCache, TheLeastRecentlyFreedGoesFirstWhateverItsSize) {
  RecordingDriver driver;
  AllocationCache cache(driver.backend(), 10000);
  void* large = cache.allocate(6000);
  void* small = cache.allocate(1000);
  void* middle = cache.allocate(3000);
  cache.free(large);
  cache.free(small);
  cache.free(middle);  // 10000 bytes: at the limit, all kept
  EXPECT_EQ(cache.cached_bytes(), 10000u);
  // Taking the small block back out and freeing another pushes the cache over its limit: the
  // large one, freed first, leaves, not the smallest.
  EXPECT_EQ(cache.allocate(1000), small);
  void* other = cache.allocate(2000);
  cache.free(other);
  EXPECT_EQ(driver.live.count(large), 0u);
  EXPECT_EQ(driver.live.count(middle), 1u);
  EXPECT_EQ(driver.live.count(other), 1u);
  EXPECT_EQ(cache.cached_bytes(), 5000u);
  // Freed again, the small block is now the most recent: the middle one goes before it.
  cache.free(small);
  cache.free(cache.allocate(6000));
  EXPECT_EQ(driver.live.count(middle), 0u);
  EXPECT_EQ(driver.live.count(small), 1u);
}

TEST(AllocationCache, ALowerLimitReleasesAtOnceAndZeroKeepsNothing) {
  RecordingDriver driver;
  AllocationCache cache(driver.backend(), 10000);
  void* a = cache.allocate(3000);
  void* b = cache.allocate(3000);
  cache.free(a);
  cache.free(b);
  cache.set_limit(4000);  // the least recently freed goes
  EXPECT_EQ(cache.cached_bytes(), 3000u);
  EXPECT_EQ(driver.live.count(a), 0u);
  EXPECT_EQ(driver.live.count(b), 1u);
  cache.set_limit(0);
  EXPECT_EQ(cache.cached_bytes(), 0u);
  void* c = cache.allocate(100);
  cache.free(c);  // with no room every free is the driver's at once
  EXPECT_EQ(cache.cached_bytes(), 0u);
  EXPECT_TRUE(driver.live.empty());
}

TEST(AllocationCache, AFailedAllocationFlushesTheCacheAndTriesOnceMore) {
  RecordingDriver driver;
  AllocationCache cache(driver.backend(), 1 << 20);
  void* a = cache.allocate(100);
  cache.free(a);
  driver.fail_next = true;  // the driver is out of memory until the cache gives its block back
  void* b = cache.allocate(5000);
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(driver.live.count(a), 0u);
  EXPECT_EQ(driver.synchronisations, 1);  // before the cached block was released
  EXPECT_EQ(cache.cached_bytes(), 0u);
  driver.fail_next = true;  // and with nothing cached a failure is the caller's
  EXPECT_EQ(cache.allocate(5000), nullptr);
  cache.free(b);
  cache.flush();
  EXPECT_TRUE(driver.live.empty());
}

}  // namespace
}  // namespace internal
}  // namespace covox

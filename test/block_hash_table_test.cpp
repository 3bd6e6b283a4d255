// BlockHashTable against std::unordered_map (the reference), on every backend, and CPU vs CUDA;
// the host BlockKeySet against std::set.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <set>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/map/block_hash_table.h"
#include "covoxslam/map/block_key.h"
#include "covoxslam/map/block_key_set.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::DeviceTest;

struct IndexHash {
  size_t operator()(const Index3D& i) const {
    return std::hash<uint64_t>()((uint64_t(uint32_t(i.x)) << 40) ^ (uint64_t(uint32_t(i.y)) << 20) ^
                                 uint32_t(i.z));
  }
};
using ReferenceMap = std::unordered_map<Index3D, uint32_t, IndexHash>;

// `count` keys drawn from `distinct` distinct blocks of a cube around the origin: heavy
// duplication, negative indices included. count == distinct gives each block exactly once.
std::vector<Index3D> random_blocks(size_t count, size_t distinct, uint32_t seed,
                                   int32_t half_extent = 2000) {
  std::mt19937 random(seed);
  std::uniform_int_distribution<int32_t> coordinate(-half_extent, half_extent);
  std::unordered_set<Index3D, IndexHash> pool_set;
  std::vector<Index3D> pool;
  while (pool.size() < distinct) {
    const Index3D index(coordinate(random), coordinate(random), coordinate(random));
    if (pool_set.insert(index).second) pool.push_back(index);
  }
  if (count == distinct) return pool;  // every key exactly once, in random order
  std::uniform_int_distribution<size_t> pick(0, distinct - 1);
  std::vector<Index3D> keys(count);
  for (auto& key : keys) key = pool[pick(random)];
  return keys;
}

struct ActivateOutput {
  std::vector<uint32_t> slots;
  std::vector<uint8_t> is_new;
  map::ActivateResult result;
};

ActivateOutput activate(map::BlockHashTable& table, const std::vector<Index3D>& keys) {
  auto keys_device = Buffer<Index3D>::from_host(table.device(), keys);
  Buffer<uint32_t> slots(table.device(), keys.size());
  Buffer<uint8_t> is_new(table.device(), keys.size());
  ActivateOutput output;
  output.result = table.activate(keys_device.data(), keys.size(), slots.data(), is_new.data());
  output.slots = slots.to_host();
  output.is_new = is_new.to_host();
  return output;
}

std::vector<uint32_t> find(const map::BlockHashTable& table, const std::vector<Index3D>& keys) {
  auto keys_device = Buffer<Index3D>::from_host(table.device(), keys);
  Buffer<uint32_t> slots(table.device(), keys.size());
  table.find(keys_device.data(), keys.size(), slots.data());
  return slots.to_host();
}

int64_t erase(map::BlockHashTable& table, const std::vector<Index3D>& keys) {
  auto keys_device = Buffer<Index3D>::from_host(table.device(), keys);
  return table.erase(keys_device.data(), keys.size());
}

// Applies one activate batch to the reference and checks the table's answer against it:
// known keys keep their slot, each new key is flagged new exactly once, every occurrence of a
// key in the batch gets the same slot, and no two live keys share a slot.
void activate_and_check(map::BlockHashTable& table, ReferenceMap& reference,
                        const std::vector<Index3D>& keys) {
  const ActivateOutput output = activate(table, keys);
  ASSERT_TRUE(output.result.ok());
  ReferenceMap batch_new;
  int64_t flagged_new = 0;
  for (size_t i = 0; i < keys.size(); ++i) {
    const uint32_t slot = output.slots[i];
    ASSERT_NE(slot, map::kInvalidSlot) << "key " << i;
    auto known = reference.find(keys[i]);
    if (known != reference.end()) {
      ASSERT_EQ(slot, known->second) << "a known key changed its slot";
      ASSERT_EQ(output.is_new[i], 0);
      continue;
    }
    auto [it, first_time] = batch_new.emplace(keys[i], slot);
    if (!first_time) {
      ASSERT_EQ(slot, it->second) << "duplicates of one key got different slots";
    }
    flagged_new += output.is_new[i];
  }
  ASSERT_EQ(flagged_new, static_cast<int64_t>(batch_new.size()))
      << "each new key must be flagged new exactly once";
  ASSERT_EQ(output.result.num_new, static_cast<int64_t>(batch_new.size()));
  for (const auto& entry : batch_new) reference.insert(entry);
  ASSERT_EQ(table.size(), static_cast<int64_t>(reference.size()));
  std::unordered_set<uint32_t> used_slots;
  for (const auto& entry : reference) {
    ASSERT_TRUE(used_slots.insert(entry.second).second)
        << "two live keys share slot " << entry.second;
    ASSERT_LT(entry.second, table.slot_count());
  }
}

void expect_table_matches(const map::BlockHashTable& table, const ReferenceMap& reference) {
  std::vector<Index3D> keys;
  std::vector<uint32_t> expected;
  for (const auto& entry : reference) {
    keys.push_back(entry.first);
    expected.push_back(entry.second);
  }
  EXPECT_EQ(find(table, keys), expected);
  EXPECT_EQ(table.size(), static_cast<int64_t>(reference.size()));
}

class BlockHashTableTest : public DeviceTest {};

TEST_P(BlockHashTableTest, MatchesUnorderedMapOnAMillionDuplicatedKeys) {
  map::BlockHashTable table(device(), map::BlockHashTableConfig{1 << 12, 0.75, true});
  ReferenceMap reference;
  const auto keys = random_blocks(1200000, 150000, 1);  // each key about 8 times
  const size_t batch = 200000;
  for (size_t begin = 0; begin < keys.size(); begin += batch) {
    const std::vector<Index3D> part(keys.begin() + begin,
                                    keys.begin() + std::min(keys.size(), begin + batch));
    activate_and_check(table, reference, part);
  }
  expect_table_matches(table, reference);
  EXPECT_LE(table.occupancy(), 0.75);
  // Absent keys are not found.
  const auto absent = random_blocks(20000, 20000, 99, 1000000);
  const auto absent_slots = find(table, absent);
  for (size_t i = 0; i < absent.size(); ++i) {
    if (!reference.count(absent[i])) {
      ASSERT_EQ(absent_slots[i], map::kInvalidSlot);
    }
  }
}

TEST_P(BlockHashTableTest, OneBatchOfOneKeyRepeatedRacesToASingleInsert) {
  map::BlockHashTable table(device());
  const std::vector<Index3D> keys(100000, Index3D(-3, 7, 11));
  const ActivateOutput output = activate(table, keys);
  EXPECT_EQ(output.result.num_new, 1);
  EXPECT_EQ(std::count(output.is_new.begin(), output.is_new.end(), 1), 1);
  EXPECT_TRUE(std::all_of(output.slots.begin(), output.slots.end(),
                          [&](uint32_t s) { return s == output.slots[0]; }));
  EXPECT_EQ(table.size(), 1);
}

TEST_P(BlockHashTableTest, EraseAndReinsertCyclesReuseSlots) {
  map::BlockHashTable table(device(), map::BlockHashTableConfig{1 << 10, 0.75, true});
  ReferenceMap reference;
  const auto universe = random_blocks(60000, 60000, 3);  // distinct
  activate_and_check(table, reference, universe);
  std::mt19937 random(5);
  for (int cycle = 0; cycle < 4; ++cycle) {
    std::vector<Index3D> to_erase;
    for (const auto& key : universe) {
      if (random() % 2 && reference.count(key)) to_erase.push_back(key);
    }
    // Duplicates in an erase batch and keys that are absent are both harmless.
    to_erase.push_back(to_erase.front());
    to_erase.push_back(Index3D(123456, -654321, 7));
    const int64_t erased = erase(table, to_erase);
    std::set<Index3D> distinct_erased(to_erase.begin(), to_erase.end() - 1);
    EXPECT_EQ(erased, static_cast<int64_t>(distinct_erased.size()));
    for (const auto& key : distinct_erased) reference.erase(key);
    expect_table_matches(table, reference);
    const auto gone =
        find(table, std::vector<Index3D>(distinct_erased.begin(), distinct_erased.end()));
    EXPECT_TRUE(
        std::all_of(gone.begin(), gone.end(), [](uint32_t s) { return s == map::kInvalidSlot; }));
    // Re-insert everything (mix of present and absent keys).
    activate_and_check(table, reference, universe);
    // Freed slots are reused: the slot range never exceeds the live maximum.
    EXPECT_EQ(table.slot_count(), universe.size());
  }
}

TEST_P(BlockHashTableTest, GrowsThroughSeveralRehashesKeepingSlots) {
  map::BlockHashTable table(device(), map::BlockHashTableConfig{64, 0.7, true});
  ReferenceMap reference;
  const auto keys = random_blocks(300000, 100000, 7);
  for (size_t begin = 0; begin < keys.size(); begin += 25000) {
    const std::vector<Index3D> part(keys.begin() + begin, keys.begin() + begin + 25000);
    activate_and_check(table, reference, part);  // checks known keys keep their slots
  }
  EXPECT_GE(table.rehash_count(), 3);
  EXPECT_LE(table.occupancy(), 0.7);
  expect_table_matches(table, reference);
}

TEST_P(BlockHashTableTest, StaysCorrectAtHighLoadFactorsWithoutGrowth) {
  for (const double load : {0.5, 0.7, 0.85, 0.9}) {
    const size_t key_count = 200000;
    const uint64_t buckets = static_cast<uint64_t>(key_count / load);
    map::BlockHashTable table(device(), map::BlockHashTableConfig{buckets, 0.5, false});
    ReferenceMap reference;
    const auto keys = random_blocks(key_count, key_count, 11);  // distinct
    activate_and_check(table, reference, keys);
    EXPECT_EQ(table.bucket_count(), buckets);
    EXPECT_NEAR(table.load_factor(), load, 0.01);
    expect_table_matches(table, reference);
  }
}

TEST_P(BlockHashTableTest, FullTableFailsCleanlyAndSaysSo) {
  map::BlockHashTable table(device(), map::BlockHashTableConfig{1000, 0.5, false});
  const auto keys = random_blocks(1500, 1500, 13);
  const ActivateOutput output = activate(table, keys);
  EXPECT_EQ(output.result.num_new, 1000);
  EXPECT_EQ(output.result.num_failed_full, 500);
  EXPECT_FALSE(output.result.ok());
  EXPECT_EQ(table.size(), 1000);
  EXPECT_EQ(table.total_failed_full(), 500);
  // The keys that made it are all findable with the slot they were given; the others are not.
  const auto found = find(table, keys);
  for (size_t i = 0; i < keys.size(); ++i) EXPECT_EQ(found[i], output.slots[i]);
}

TEST_P(BlockHashTableTest, RejectsOutOfRangeKeysWithoutWrapping) {
  map::BlockHashTable table(device());
  const std::vector<Index3D> keys = {
      Index3D(map::kMaxBlockIndex, map::kMinBlockIndex, 0),  // the extremes are valid
      Index3D(map::kMaxBlockIndex + 1, 0, 0),                // would wrap onto kMinBlockIndex
      Index3D(0, map::kMinBlockIndex - 1, 0), Index3D(0, 0, 1 << 30),
      Index3D(map::kMinBlockIndex, 0, 0)};
  const ActivateOutput output = activate(table, keys);
  EXPECT_EQ(output.result.num_out_of_range, 3);
  EXPECT_EQ(output.result.num_new, 2);
  EXPECT_EQ(table.total_out_of_range(), 3);
  EXPECT_NE(output.slots[0], map::kInvalidSlot);
  EXPECT_EQ(output.slots[1], map::kInvalidSlot);
  EXPECT_EQ(output.slots[2], map::kInvalidSlot);
  EXPECT_EQ(output.slots[3], map::kInvalidSlot);
  EXPECT_NE(output.slots[4], map::kInvalidSlot);
  EXPECT_NE(output.slots[4], output.slots[0]);
  // An out-of-range key is never found, not even as its wrapped twin.
  const auto found = find(table, {Index3D(map::kMaxBlockIndex + 1, 0, 0)});
  EXPECT_EQ(found[0], map::kInvalidSlot);
}

TEST_P(BlockHashTableTest, ExportListsEveryLiveEntry) {
  map::BlockHashTable table(device());
  ReferenceMap reference;
  activate_and_check(table, reference, random_blocks(5000, 3000, 17));
  erase(table, {reference.begin()->first});
  reference.erase(reference.begin());
  Buffer<Index3D> keys(device());
  Buffer<uint32_t> slots(device());
  table.export_entries(&keys, &slots);
  const auto host_keys = keys.to_host();
  const auto host_slots = slots.to_host();
  ASSERT_EQ(host_keys.size(), reference.size());
  for (size_t i = 0; i < host_keys.size(); ++i)
    EXPECT_EQ(reference.at(host_keys[i]), host_slots[i]);
}

TEST(BlockKey, PacksAndUnpacksTheWholeRange) {
  for (int32_t v : {map::kMinBlockIndex, -1, 0, 1, map::kMaxBlockIndex}) {
    const Index3D index(v, -v - 1 >= map::kMinBlockIndex ? -v - 1 : v, v / 2);
    EXPECT_EQ(map::unpack_block_key(map::pack_block_key(index)), index);
    EXPECT_LT(map::pack_block_key(index), map::kInvalidBlockKey);
  }
  EXPECT_EQ(map::pack_block_key(Index3D(map::kMaxBlockIndex + 1, 0, 0)), map::kInvalidBlockKey);
}

// activate_queued + finish_queued_activation against activate() on a twin table: the first
// *count keys of a longer array (duplicates, keys already present, freed slots to reuse, one key
// outside the key range). Which duplicate of a new key wins its insert (and so the order in which
// new keys take slots) depends on thread timing, so the check is the contract: known keys keep
// their slot, each new key is flagged once and all its occurrences share a slot, the new keys take
// the same set of slots as activate() hands out, entries past the count get kInvalidSlot; other
// calls are refused until the activation is finished.
TEST_P(BlockHashTableTest, QueuedActivationMatchesActivate) {
  const map::BlockHashTableConfig config{1 << 14, 0.75, true};
  map::BlockHashTable queued(device(), config), direct(device(), config);
  const auto first = random_blocks(3000, 3000, 5);
  for (map::BlockHashTable* table : {&queued, &direct}) {
    activate(*table, first);
    erase(*table, std::vector<Index3D>(first.begin(), first.begin() + 500));  // slots to reuse
  }
  std::vector<Index3D> keys = random_blocks(6000, 2500, 6);
  keys.insert(keys.begin() + 10, first.begin() + 100,
              first.begin() + 1100);                  // erased and live keys
  keys[20] = Index3D(map::kMaxBlockIndex + 1, 0, 0);  // rejected
  const int64_t count = 5200, bound = static_cast<int64_t>(keys.size());
  const std::vector<Index3D> counted(keys.begin(), keys.begin() + count);
  const std::vector<uint32_t> before = find(queued, counted);

  auto keys_device = Buffer<Index3D>::from_host(device(), keys);
  auto count_device = Buffer<uint32_t>::from_host(device(), {static_cast<uint32_t>(count)});
  Buffer<uint32_t> slots(device(), bound), totals(device(), 2);
  Buffer<uint8_t> is_new(device(), bound);
  Stream stream(device());
  ASSERT_TRUE(queued.activate_queued(keys_device.data(), count_device.data(), bound, slots.data(),
                                     is_new.data(), totals.data(), stream));
  EXPECT_THROW(activate(queued, counted), Error);
  EXPECT_THROW(erase(queued, counted), Error);
  stream.synchronize();
  const std::vector<uint32_t> host_totals = totals.to_host();
  const map::ActivateResult result =
      queued.finish_queued_activation(host_totals[0], host_totals[1], stream);
  const ActivateOutput expected = activate(direct, counted);
  EXPECT_EQ(result.num_new, expected.result.num_new);
  EXPECT_EQ(result.num_out_of_range, 1);
  EXPECT_EQ(expected.result.num_out_of_range, 1);
  EXPECT_EQ(result.num_failed_full, 0);

  const std::vector<uint32_t> host_slots = slots.to_host();
  const std::vector<uint8_t> host_is_new = is_new.to_host();
  std::unordered_map<Index3D, uint32_t, IndexHash> new_slots;
  int64_t flagged = 0;
  for (int64_t i = 0; i < count; ++i) {
    if (i == 20) {
      ASSERT_EQ(host_slots[i], map::kInvalidSlot);
      continue;
    }
    if (before[i] != map::kInvalidSlot) {
      ASSERT_EQ(host_slots[i], before[i]) << "a known key changed its slot, key " << i;
      ASSERT_EQ(host_is_new[i], 0) << "key " << i;
      continue;
    }
    const auto [it, first_time] = new_slots.emplace(keys[i], host_slots[i]);
    if (!first_time) {
      ASSERT_EQ(host_slots[i], it->second) << "duplicates got different slots, key " << i;
    }
    flagged += host_is_new[i];
  }
  EXPECT_EQ(flagged, static_cast<int64_t>(new_slots.size()));
  EXPECT_EQ(result.num_new, static_cast<int64_t>(new_slots.size()));
  for (int64_t i = count; i < bound; ++i) {
    ASSERT_EQ(host_slots[i], map::kInvalidSlot) << "key " << i;
    ASSERT_EQ(host_is_new[i], 0) << "key " << i;
  }
  std::set<uint32_t> queued_new, direct_new;
  for (const auto& entry : new_slots) queued_new.insert(entry.second);
  for (int64_t i = 0; i < count; ++i) {
    if (expected.is_new[i]) direct_new.insert(expected.slots[i]);
  }
  EXPECT_EQ(queued_new, direct_new);
  EXPECT_EQ(queued.size(), direct.size());
  EXPECT_EQ(queued.slot_count(), direct.slot_count());
  // Both tables go on alike (distinct keys take slots in input order).
  const auto more = random_blocks(2000, 2000, 7, 100000);
  EXPECT_EQ(activate(queued, more).slots, activate(direct, more).slots);
}

TEST_P(BlockHashTableTest, QueuedActivationDeclinesWhenTheTableMightGrow) {
  map::BlockHashTable table(device(), map::BlockHashTableConfig{1024, 0.75, true});
  const auto keys = random_blocks(1000, 1000, 8);
  auto keys_device = Buffer<Index3D>::from_host(device(), keys);
  auto count_device = Buffer<uint32_t>::from_host(device(), {10u});
  Buffer<uint32_t> slots(device(), keys.size()), totals(device(), 2);
  Stream stream(device());
  // 1000 possible new keys do not fit under 0.75 x 1024: the caller must take activate().
  EXPECT_FALSE(table.activate_queued(keys_device.data(), count_device.data(), 1000, slots.data(),
                                     nullptr, totals.data(), stream));
  EXPECT_EQ(table.size(), 0);
  EXPECT_NO_THROW(activate(table, keys));  // nothing was left queued
  EXPECT_EQ(table.size(), 1000);
}

// The in-kernel activation (block_activator.h) against activate() on a twin table, on the CPU
// twin (where a test can call it from its own parallel loop; on the GPU it runs inside the TSDF
// frames' scan of their block marks, which the TSDF tests check against the CPU): distinct keys,
// known ones keep their slot, the new ones take the same set of slots as activate() hands out
// (freed ones first), a key outside the key range is rejected and counted, and the table is
// locked until the totals are handed back.
TEST(BlockActivatorTest, InKernelActivationMatchesActivate) {
  const map::BlockHashTableConfig config{1 << 14, 0.75, true};
  map::BlockHashTable in_kernel(Device::kCpu, config), direct(Device::kCpu, config);
  const auto first = random_blocks(3000, 3000, 5);
  for (map::BlockHashTable* table : {&in_kernel, &direct}) {
    activate(*table, first);
    erase(*table, std::vector<Index3D>(first.begin(), first.begin() + 500));  // slots to reuse
  }
  std::vector<Index3D> keys(first.begin() + 100, first.begin() + 1100);  // erased and live keys
  for (const Index3D& key : random_blocks(2500, 2500, 6, 100000)) keys.push_back(key);
  keys.push_back(Index3D(map::kMaxBlockIndex + 1, 0, 0));  // rejected
  const std::vector<uint32_t> before = find(in_kernel, keys);

  const Stream stream(Device::kCpu);
  map::BlockActivator activator;
  ASSERT_TRUE(
      in_kernel.begin_in_kernel_activation(static_cast<int64_t>(keys.size()), &activator, stream));
  EXPECT_THROW(activate(in_kernel, keys), Error);
  std::vector<uint32_t> slots(keys.size());
  std::vector<uint8_t> is_new(keys.size());
#pragma omp parallel for
  for (int64_t i = 0; i < static_cast<int64_t>(keys.size()); ++i) {
    bool fresh = false;
    slots[i] = activator.activate(keys[i], &fresh);
    is_new[i] = fresh;
  }
  uint32_t totals[3];
  activator.hand_over_totals(totals);
  const map::ActivateResult result =
      in_kernel.finish_in_kernel_activation(totals[0], totals[1], totals[2]);
  const ActivateOutput expected = activate(direct, keys);
  EXPECT_EQ(result.num_new, expected.result.num_new);
  EXPECT_EQ(result.num_out_of_range, 1);
  EXPECT_EQ(result.num_failed_full, 0);
  std::set<uint32_t> in_kernel_new, direct_new;
  for (size_t i = 0; i < keys.size(); ++i) {
    if (i + 1 == keys.size()) {
      EXPECT_EQ(slots[i], map::kInvalidSlot);
      continue;
    }
    if (before[i] != map::kInvalidSlot) {
      ASSERT_EQ(slots[i], before[i]) << "a known key changed its slot, key " << i;
      ASSERT_EQ(is_new[i], 0) << "key " << i;
    } else {
      ASSERT_EQ(is_new[i], 1) << "key " << i;
      in_kernel_new.insert(slots[i]);
    }
    if (expected.is_new[i]) direct_new.insert(expected.slots[i]);
  }
  EXPECT_EQ(in_kernel_new.size(), static_cast<size_t>(result.num_new));
  EXPECT_EQ(in_kernel_new, direct_new);
  EXPECT_EQ(find(in_kernel, keys), slots);
  EXPECT_EQ(in_kernel.size(), direct.size());
  EXPECT_EQ(in_kernel.slot_count(), direct.slot_count());
  // The counters were cleared for the next activation.
  ASSERT_TRUE(in_kernel.begin_in_kernel_activation(1, &activator, stream));
  activator.hand_over_totals(totals);
  EXPECT_EQ(totals[0] + totals[1] + totals[2], 0u);
  in_kernel.finish_in_kernel_activation(0, 0, 0);
  EXPECT_NO_THROW(activate(in_kernel, keys));
}

// A caller stopped before it finished an activation (an exception in a TSDF frame) abandons it,
// in-kernel or queued: the table takes later calls, and the keys inserted so far keep the slots
// they got, none of which is handed out again.
TEST(BlockActivatorTest, AnAbandonedActivationLeavesTheTableConsistent) {
  map::BlockHashTable table(Device::kCpu, map::BlockHashTableConfig{1 << 12, 0.75, true});
  const auto keys = random_blocks(600, 600, 9);
  const Stream stream(Device::kCpu);
  map::BlockActivator activator;
  ASSERT_TRUE(
      table.begin_in_kernel_activation(static_cast<int64_t>(keys.size()), &activator, stream));
  std::vector<uint32_t> slots(300);
  for (size_t i = 0; i < 300; ++i) {
    bool fresh = false;
    slots[i] = activator.activate(keys[i], &fresh);
    ASSERT_TRUE(fresh);
  }
  EXPECT_THROW(activate(table, keys), Error);  // pending
  table.abandon_pending_activation(nullptr, stream);
  table.abandon_pending_activation(nullptr, stream);  // nothing pending: nothing to do
  EXPECT_EQ(table.size(), 300);
  EXPECT_EQ(table.slot_count(), 300u);
  // A queued activation abandoned after its kernels ran: finished from the totals it wrote.
  const std::vector<Index3D> more(keys.begin() + 250, keys.begin() + 400);  // 50 known, 100 new
  auto more_device = Buffer<Index3D>::from_host(Device::kCpu, more);
  auto count_device =
      Buffer<uint32_t>::from_host(Device::kCpu, {static_cast<uint32_t>(more.size())});
  Buffer<uint32_t> more_slots(Device::kCpu, more.size()), totals(Device::kCpu, 2);
  ASSERT_TRUE(table.activate_queued(more_device.data(), count_device.data(),
                                    static_cast<int64_t>(more.size()), more_slots.data(), nullptr,
                                    totals.data(), stream));
  table.abandon_pending_activation(totals.data(), stream);
  EXPECT_EQ(table.size(), 400);
  EXPECT_EQ(table.slot_count(), 400u);
  const ActivateOutput all = activate(table, keys);
  EXPECT_EQ(all.result.num_new, 200);
  std::set<uint32_t> distinct(all.slots.begin(), all.slots.end());
  EXPECT_EQ(distinct.size(), keys.size());
  for (size_t i = 0; i < 300; ++i) EXPECT_EQ(all.slots[i], slots[i]) << "key " << i;
  const std::vector<uint32_t> queued_slots = more_slots.to_host();
  for (size_t i = 0; i < more.size(); ++i)
    EXPECT_EQ(all.slots[250 + i], queued_slots[i]) << "key " << 250 + i;
}

TEST(BlockHashTableConfigCheck, RejectsBadParameters) {
  EXPECT_THROW(map::BlockHashTable(Device::kCpu, map::BlockHashTableConfig{1024, 1.5, true}),
               Error);
  EXPECT_THROW(map::BlockHashTable(Device::kCpu, map::BlockHashTableConfig{0, 0.5, true}), Error);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(BlockHashTableTest);

// Same batches on both backends: batches of distinct keys get identical slots (slot order is
// the input order of new keys), and with duplicated batches both map keys to slots one-to-one.
TEST(BlockHashTableParity, CpuAndCudaAssignConsistentSlots) {
  COVOX_SKIP_WITHOUT_GPU();
  map::BlockHashTable cpu(Device::kCpu, map::BlockHashTableConfig{256, 0.75, true});
  map::BlockHashTable gpu(Device::kCuda, map::BlockHashTableConfig{256, 0.75, true});
  const auto distinct = random_blocks(200000, 200000, 21);
  const auto cpu_distinct = activate(cpu, distinct);
  const auto gpu_distinct = activate(gpu, distinct);
  EXPECT_EQ(cpu_distinct.slots, gpu_distinct.slots);
  EXPECT_EQ(cpu_distinct.is_new, gpu_distinct.is_new);

  const auto duplicated = random_blocks(500000, 50000, 23, 3000);
  const auto cpu_dup = activate(cpu, duplicated);
  const auto gpu_dup = activate(gpu, duplicated);
  EXPECT_EQ(cpu_dup.result.num_new, gpu_dup.result.num_new);
  std::unordered_map<uint32_t, uint32_t> cpu_to_gpu;
  for (size_t i = 0; i < duplicated.size(); ++i) {
    auto [it, inserted] = cpu_to_gpu.emplace(cpu_dup.slots[i], gpu_dup.slots[i]);
    ASSERT_EQ(it->second, gpu_dup.slots[i]) << "slot partition differs at " << i;
  }
  EXPECT_EQ(cpu.size(), gpu.size());
  EXPECT_EQ(find(cpu, distinct), find(gpu, distinct));
}

// The host set answers as std::set does: clustered keys (a submap's neighbouring blocks) with
// duplicates, the reserved keys left out, and queries mostly outside the set.
TEST(BlockKeySetTest, MatchesStdSetOnClusteredKeysWithDuplicates) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int32_t> axis(-40, 40);
  std::vector<uint64_t> keys;
  for (int k = 0; k < 3000; ++k)
    keys.push_back(map::pack_block_key(Index3D(axis(rng), axis(rng), axis(rng) / 8)));
  keys.push_back(map::kInvalidBlockKey);
  keys.push_back(map::kEmptyBlockKey);
  keys.push_back(map::kErasedBlockKey);
  const map::BlockKeySet set(keys);
  std::set<uint64_t> reference;
  for (uint64_t key : keys)
    if (map::is_live_block_key(key)) reference.insert(key);
  EXPECT_EQ(set.size(), reference.size());
  EXPECT_LT(reference.size(), 3000u);  // the draw did repeat keys
  int64_t found = 0;
  for (int x = -45; x <= 45; ++x) {
    for (int y = -45; y <= 45; ++y) {
      for (int z = -6; z <= 6; ++z) {
        const uint64_t key = map::pack_block_key(Index3D(x, y, z));
        ASSERT_EQ(set.contains(key), reference.count(key) == 1) << x << " " << y << " " << z;
        found += set.contains(key) ? 1 : 0;
      }
    }
  }
  EXPECT_EQ(found, static_cast<int64_t>(reference.size()));
  EXPECT_FALSE(set.contains(map::kInvalidBlockKey));
  EXPECT_FALSE(set.contains(map::kEmptyBlockKey));
  EXPECT_FALSE(map::BlockKeySet().contains(map::pack_block_key(Index3D(0, 0, 0))));
}

}  // namespace
}  // namespace covox

// The parallel primitives on each backend against plain sequential C++, and CPU vs CUDA parity.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <numeric>
#include <random>
#include <utility>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device_algorithms.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/run_sums.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::DeviceTest;

std::vector<uint64_t> random_keys(size_t count, uint64_t distinct, uint32_t seed) {
  std::mt19937_64 random(seed);
  std::uniform_int_distribution<uint64_t> pick(0, distinct - 1);
  std::vector<uint64_t> keys(count);
  for (auto& key : keys) key = pick(random) * 2654435761ull;  // spread over 64 bits
  return keys;
}

class CorePrimitivesTest : public DeviceTest {};

TEST_P(CorePrimitivesTest, ScaleAddMatchesSequentialLoop) {
  const int64_t count = 100003;  // not a multiple of any block size
  std::vector<float> x(count), y(count);
  for (int64_t i = 0; i < count; ++i) {
    x[i] = 0.5f * i;
    y[i] = 3.0f - i;
  }
  auto x_device = Buffer<float>::from_host(device(), x);
  auto y_device = Buffer<float>::from_host(device(), y);
  algorithms::scale_add(device(), Stream(device()), 2.0f, x_device.data(), y_device.data(), count);
  const auto result = y_device.to_host();
  for (int64_t i = 0; i < count; ++i) ASSERT_FLOAT_EQ(result[i], 2.0f * x[i] + y[i]) << i;
}

TEST_P(CorePrimitivesTest, ExclusiveScanMatchesStd) {
  std::mt19937 random(7);
  std::vector<uint32_t> values(1 << 20);
  for (auto& v : values) v = random() % 3;
  std::vector<uint32_t> expected(values.size());
  std::exclusive_scan(values.begin(), values.end(), expected.begin(), 0u);
  auto in = Buffer<uint32_t>::from_host(device(), values);
  Buffer<uint32_t> out(device(), values.size());
  algorithms::exclusive_scan(device(), Stream(device()), in.data(), in.size(), out.data());
  EXPECT_EQ(out.to_host(), expected);
}

// The single-pass scan: one tile, tile edges, look-back past windows of 32 tiles, full 32-bit
// values (the sums wrap, as std's do), each value read exactly once; then in place, three scans
// queued back to back on one stream (each with its own epoch of tile descriptors).
TEST_P(CorePrimitivesTest, ScanOfValuesReadsEachOnceAndMatchesStd) {
  const Stream stream(device());
  std::mt19937 random(3);
  for (const int64_t count : {int64_t(1), int64_t(2047), int64_t(2048), int64_t(2049),
                              int64_t(65 * 2048 + 5), int64_t(300001)}) {
    std::vector<uint32_t> values(count);
    for (auto& v : values) v = static_cast<uint32_t>(random());
    std::vector<uint32_t> expected(count);
    std::exclusive_scan(values.begin(), values.end(), expected.begin(), 0u);
    auto in = Buffer<uint32_t>::from_host(device(), values);
    Buffer<uint32_t> out(device(), count);
    Buffer<uint32_t> calls(device(), count);
    calls.fill_bytes(0, stream);
    algorithms::scan_values_once(device(), stream, in.data(), count, out.data(), calls.data());
    ASSERT_EQ(out.to_host(stream), expected) << count;
    ASSERT_EQ(calls.to_host(stream), std::vector<uint32_t>(count, 1u)) << count;
    // The prefixes handed to a functor instead, each once, after its value was read.
    out.fill_bytes(0, stream);
    calls.fill_bytes(0, stream);
    algorithms::scan_values_once(device(), stream, in.data(), count, out.data(), calls.data(),
                                 true);
    ASSERT_EQ(out.to_host(stream), expected) << count;
    ASSERT_EQ(calls.to_host(stream), std::vector<uint32_t>(count, (1u << 16) + 1u)) << count;
    for (int round = 0; round < 3; ++round) {
      algorithms::exclusive_scan(device(), stream, in.data(), count, in.data());
      std::exclusive_scan(values.begin(), values.end(), values.begin(), 0u);
    }
    ASSERT_EQ(in.to_host(stream), values) << count;
  }
}

// A pending read-back returns the bytes as they were when it was queued (later work on the stream
// does not change them), one per thread at a time, at most kMaxBytes; one dropped unwaited frees
// its thread's slot.
TEST_P(CorePrimitivesTest, PendingReadBackReturnsTheQueuedBytesOneAtATime) {
  const Stream stream(device());
  auto words = Buffer<uint32_t>::from_host(device(), std::vector<uint32_t>{7u, 11u, 13u}, stream);
  {
    PendingReadBack pending(words.data(), device(), 3 * sizeof(uint32_t), stream);
    EXPECT_THROW({ PendingReadBack second(words.data(), device(), sizeof(uint32_t), stream); },
                 Error);
    words.fill_bytes(0, stream);  // queued after the copy
    uint32_t host[3] = {0u, 0u, 0u};
    pending.wait(host);
    EXPECT_EQ(host[0], 7u);
    EXPECT_EQ(host[1], 11u);
    EXPECT_EQ(host[2], 13u);
    EXPECT_THROW(pending.wait(host), Error);
  }
  EXPECT_THROW(
      { PendingReadBack too_big(words.data(), device(), PendingReadBack::kMaxBytes + 1, stream); },
      Error);
  { PendingReadBack dropped(words.data(), device(), sizeof(uint32_t), stream); }
  PendingReadBack again(words.data(), device(), sizeof(uint32_t), stream);
  uint32_t first = 1u;
  again.wait(&first);
  EXPECT_EQ(first, 0u);
}

TEST_P(CorePrimitivesTest, SortByKeyIsStableAndMatchesStd) {
  const auto keys = random_keys(500000, 1000, 11);  // many equal keys: stability matters
  std::vector<uint32_t> values(keys.size());
  std::iota(values.begin(), values.end(), 0u);
  std::vector<std::pair<uint64_t, uint32_t>> expected;
  for (size_t i = 0; i < keys.size(); ++i) expected.emplace_back(keys[i], values[i]);
  std::stable_sort(expected.begin(), expected.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });

  auto keys_device = Buffer<uint64_t>::from_host(device(), keys);
  auto values_device = Buffer<uint32_t>::from_host(device(), values);
  algorithms::sort_by_key(device(), Stream(device()), keys_device.data(), values_device.data(),
                          keys.size());
  const auto sorted_keys = keys_device.to_host();
  const auto sorted_values = values_device.to_host();
  for (size_t i = 0; i < keys.size(); ++i) {
    ASSERT_EQ(sorted_keys[i], expected[i].first) << i;
    ASSERT_EQ(sorted_values[i], expected[i].second) << i;
  }
}

// The bit-limited radix sort against std::stable_sort, for odd and even numbers of 8-bit passes
// (an odd count ends in the scratch arrays and is copied back), with partly used last digits.
// Run on both backends, this also shows that they give the same order.
TEST_P(CorePrimitivesTest, RadixSortOfLowBitsIsStableAndMatchesStd) {
  for (int key_bits : {7, 16, 17, 22, 27, 33, 64}) {
    const uint64_t limit = key_bits == 64 ? ~uint64_t(0) : (uint64_t(1) << key_bits) - 1;
    std::mt19937_64 random(key_bits);
    std::vector<uint64_t> keys(300001);
    for (auto& key : keys)
      key = (random() % 4096) * (limit / 4096) + (random() % 2);  // many equal keys
    std::vector<uint32_t> values(keys.size());
    std::iota(values.begin(), values.end(), 0u);
    std::vector<std::pair<uint64_t, uint32_t>> expected;
    for (size_t i = 0; i < keys.size(); ++i) expected.emplace_back(keys[i], values[i]);
    std::stable_sort(expected.begin(), expected.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });

    auto keys_device = Buffer<uint64_t>::from_host(device(), keys);
    auto values_device = Buffer<uint32_t>::from_host(device(), values);
    Buffer<uint64_t> keys_alt(device(), keys.size());
    Buffer<uint32_t> values_alt(device(), keys.size());
    const Stream stream(device());
    algorithms::radix_sort_pairs(device(), stream, keys_device.data(), values_device.data(),
                                 keys.size(), key_bits, keys_alt.data(), values_alt.data());
    const auto sorted_keys = keys_device.to_host(stream);
    const auto sorted_values = values_device.to_host(stream);
    for (size_t i = 0; i < keys.size(); ++i) {
      ASSERT_EQ(sorted_keys[i], expected[i].first) << key_bits << " bits, index " << i;
      ASSERT_EQ(sorted_values[i], expected[i].second) << key_bits << " bits, index " << i;
    }
  }
}

TEST_P(CorePrimitivesTest, ReduceByKeySumsEachRun) {
  auto keys = random_keys(300000, 5000, 3);
  std::sort(keys.begin(), keys.end());
  std::vector<float> values(keys.size());
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(i % 17) * 0.25f;
  std::vector<uint64_t> expected_keys;
  std::vector<double> expected_sums;
  for (size_t i = 0; i < keys.size(); ++i) {
    if (i == 0 || keys[i] != keys[i - 1]) {
      expected_keys.push_back(keys[i]);
      expected_sums.push_back(0.0);
    }
    expected_sums.back() += values[i];
  }
  auto keys_device = Buffer<uint64_t>::from_host(device(), keys);
  auto values_device = Buffer<float>::from_host(device(), values);
  Buffer<uint64_t> keys_out(device(), keys.size());
  Buffer<float> sums_out(device(), keys.size());
  const int64_t runs = algorithms::reduce_by_key_sum(device(), Stream(device()), keys_device.data(),
                                                     values_device.data(), keys.size(),
                                                     keys_out.data(), sums_out.data());
  ASSERT_EQ(runs, static_cast<int64_t>(expected_keys.size()));
  const auto out_keys = keys_out.to_host();
  const auto out_sums = sums_out.to_host();
  for (int64_t r = 0; r < runs; ++r) {
    ASSERT_EQ(out_keys[r], expected_keys[r]);
    // Quarter-integers sum exactly in float at these magnitudes, whatever the order.
    ASSERT_EQ(out_sums[r], static_cast<float>(expected_sums[r])) << r;
  }
}

// Runs of chosen lengths around consume_run_sums' tile size: runs of one, runs ending or
// starting exactly at a tile edge, runs crossing one edge, runs passing through several whole
// tiles, and a last tile cut short.
std::vector<uint64_t> keys_with_runs(const std::vector<int64_t>& lengths) {
  std::vector<uint64_t> keys;
  uint64_t key = 7;
  for (int64_t length : lengths) {
    keys.insert(keys.end(), static_cast<size_t>(length), key);
    key += 1 + key % 3;  // ascending, with gaps
  }
  return keys;
}

// (Each call of sum_runs_at_first runs consume_run_sums twice with one scratch buffer.)
TEST_P(CorePrimitivesTest, RunSumsHandEachRunOverOnceWithItsSum) {
  const int64_t tile = kRunSumTile;
  const std::vector<std::vector<int64_t>> cases = {
      {1, 1, 1},                                       // one short tile
      {tile, tile, 1},                                 // runs filling tiles exactly
      {tile - 1, 2, tile - 1, 1, 1},                   // runs crossing one edge
      {5, 5 * tile, 3, 2 * tile, 1},                   // runs passing through whole tiles
      {tile - 24, 24, tile, 4 * tile, 3, 77},          // runs ending at edges, runs starting there
      {2, 1, 3, 1, 1, tile / 2, 1, 1, 1, 9 * tile, 1}  // mixed
  };
  // Random run lengths: 200 000 and 700 000 records.
  std::mt19937 random(11);
  std::geometric_distribution<int64_t> length(0.02);
  std::vector<std::vector<int64_t>> all_cases = cases;
  for (const int64_t records : {200000, 700000}) {
    std::vector<int64_t> random_lengths;
    for (int64_t total = 0; total < records;) {
      random_lengths.push_back(1 + length(random));
      total += random_lengths.back();
    }
    all_cases.push_back(random_lengths);
  }
  for (size_t c = 0; c < all_cases.size(); ++c) {
    const std::vector<uint64_t> keys = keys_with_runs(all_cases[c]);
    const int64_t count = static_cast<int64_t>(keys.size());
    std::vector<double> values(keys.size());
    for (size_t i = 0; i < values.size(); ++i)
      values[i] = static_cast<double>((i * 7919) % 1000);  // exact sums
    // Each run's sum at its first record, over the first `live` records; two calls per run.
    const auto expected_sums_and_calls = [&](int64_t live) {
      std::pair<std::vector<double>, std::vector<uint32_t>> out{
          std::vector<double>(keys.size(), -1.0), std::vector<uint32_t>(keys.size(), 0u)};
      for (int64_t i = 0, first = 0; i < live; ++i) {
        if (i == 0 || keys[i] != keys[i - 1]) {
          first = i;
          out.first[first] = 0.0;
          out.second[first] = 2u;
        }
        out.first[first] += values[i];
      }
      return out;
    };
    const auto [expected, expected_calls] = expected_sums_and_calls(count);
    auto keys_device = Buffer<uint64_t>::from_host(device(), keys);
    auto values_device = Buffer<double>::from_host(device(), values);
    auto sums = Buffer<double>::from_host(device(), std::vector<double>(keys.size(), -1.0));
    auto calls = Buffer<uint32_t>::from_host(device(), std::vector<uint32_t>(keys.size(), 0u));
    algorithms::sum_runs_at_first(device(), Stream(device()), keys_device.data(),
                                  values_device.data(), count, sums.data(), calls.data());
    const auto got = sums.to_host();
    const auto got_calls = calls.to_host();
    for (int64_t i = 0; i < count; ++i) {
      ASSERT_EQ(got_calls[i], expected_calls[i]) << "case " << c << ", record " << i;
      ASSERT_EQ(got[i], expected[i]) << "case " << c << ", record " << i;
    }
    // Only the first `live` records, known on the device (the run across `live` is cut there; the
    // records after it, a long run of one key here, are not read).
    const int64_t live = count * 3 / 5;
    std::vector<uint64_t> live_keys(keys.begin(), keys.begin() + live);
    live_keys.resize(keys.size(), keys.back() + 1);
    auto live_keys_device = Buffer<uint64_t>::from_host(device(), live_keys);
    auto live_device =
        Buffer<uint32_t>::from_host(device(), std::vector<uint32_t>{static_cast<uint32_t>(live)});
    auto live_sums = Buffer<double>::from_host(device(), std::vector<double>(keys.size(), -1.0));
    auto live_calls = Buffer<uint32_t>::from_host(device(), std::vector<uint32_t>(keys.size(), 0u));
    algorithms::sum_runs_at_first(device(), Stream(device()), live_keys_device.data(),
                                  values_device.data(), count, live_sums.data(), live_calls.data(),
                                  live_device.data());
    const auto [expected_live, expected_live_calls] = expected_sums_and_calls(live);
    const auto got_live = live_sums.to_host();
    const auto got_live_calls = live_calls.to_host();
    for (int64_t i = 0; i < count; ++i) {
      ASSERT_EQ(got_live_calls[i], expected_live_calls[i])
          << "case " << c << ", live, record " << i;
      ASSERT_EQ(got_live[i], expected_live[i]) << "case " << c << ", live, record " << i;
    }
  }
}

TEST_P(CorePrimitivesTest, UniqueRemovesConsecutiveDuplicates) {
  auto keys = random_keys(200000, 20000, 5);
  std::sort(keys.begin(), keys.end());
  auto expected = keys;
  expected.erase(std::unique(expected.begin(), expected.end()), expected.end());
  auto data = Buffer<uint64_t>::from_host(device(), keys);
  const int64_t count = algorithms::unique(device(), Stream(device()), data.data(), keys.size());
  ASSERT_EQ(count, static_cast<int64_t>(expected.size()));
  auto result = data.to_host();
  result.resize(count);
  EXPECT_EQ(result, expected);
}

TEST_P(CorePrimitivesTest, ReduceSumMatchesSequentialSum) {
  std::vector<double> values(1 << 18);
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<double>(i % 1000);
  const double expected = std::accumulate(values.begin(), values.end(), 0.0);  // exact integers
  auto data = Buffer<double>::from_host(device(), values);
  EXPECT_EQ(algorithms::reduce_sum(device(), Stream(device()), data.data(), values.size()),
            expected);
}

TEST_P(CorePrimitivesTest, AtomicAddUnderHeavyContentionCountsEveryIncrement) {
  std::mt19937 random(13);
  std::vector<uint32_t> bins(2000000);
  for (auto& bin : bins) bin = random() % 7;  // 7 hot counters
  std::vector<uint32_t> expected(7, 0);
  for (uint32_t bin : bins) ++expected[bin];
  auto bins_device = Buffer<uint32_t>::from_host(device(), bins);
  Buffer<uint32_t> histogram(device(), 7);
  histogram.fill_bytes(0);
  algorithms::atomic_histogram(device(), Stream(device()), bins_device.data(), bins.size(),
                               histogram.data());
  EXPECT_EQ(histogram.to_host(), expected);
}

TEST_P(CorePrimitivesTest, AtomicCompareExchangeClaimsTheMinimumOwner) {
  std::mt19937 random(17);
  const size_t targets_count = 1000;
  std::vector<uint32_t> targets(1000000);
  for (auto& t : targets) t = random() % targets_count;
  std::vector<uint32_t> expected(targets_count, 0xffffffffu);
  for (size_t i = 0; i < targets.size(); ++i) {
    expected[targets[i]] = std::min<uint32_t>(expected[targets[i]], static_cast<uint32_t>(i));
  }
  auto targets_device = Buffer<uint32_t>::from_host(device(), targets);
  Buffer<uint32_t> owners(device(), targets_count);
  owners.fill_bytes(0xff);
  algorithms::atomic_claim_min(device(), Stream(device()), targets_device.data(), targets.size(),
                               owners.data());
  EXPECT_EQ(owners.to_host(), expected);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(CorePrimitivesTest);

// The same inputs through both backends give the same outputs.
TEST(CorePrimitivesParity, CpuAndCudaAgree) {
  COVOX_SKIP_WITHOUT_GPU();
  const auto keys = random_keys(400000, 3000, 23);
  std::vector<uint32_t> values(keys.size());
  std::iota(values.begin(), values.end(), 0u);
  std::vector<std::vector<uint64_t>> sorted(2);
  std::vector<std::vector<uint32_t>> permutation(2), scanned(2);
  std::vector<std::vector<uint64_t>> uniques(2);
  std::vector<std::vector<float>> sums(2);
  const Device devices[2] = {Device::kCpu, Device::kCuda};
  for (int d = 0; d < 2; ++d) {
    const Device device = devices[d];
    Stream stream(device);
    auto k = Buffer<uint64_t>::from_host(device, keys);
    auto v = Buffer<uint32_t>::from_host(device, values);
    algorithms::sort_by_key(device, stream, k.data(), v.data(), keys.size());
    sorted[d] = k.to_host();
    permutation[d] = v.to_host();
    Buffer<uint32_t> scan(device, values.size());
    auto flags = Buffer<uint32_t>::from_host(device, std::vector<uint32_t>(values.size(), 1u));
    algorithms::exclusive_scan(device, stream, flags.data(), values.size(), scan.data());
    scanned[d] = scan.to_host();
    std::vector<float> ones(keys.size(), 1.0f);
    auto weights = Buffer<float>::from_host(device, ones);
    Buffer<uint64_t> run_keys(device, keys.size());
    Buffer<float> run_sums(device, keys.size());
    const int64_t runs = algorithms::reduce_by_key_sum(
        device, stream, k.data(), weights.data(), keys.size(), run_keys.data(), run_sums.data());
    sums[d] = run_sums.to_host();
    sums[d].resize(runs);
    const int64_t unique_count = algorithms::unique(device, stream, k.data(), keys.size());
    uniques[d] = k.to_host();
    uniques[d].resize(unique_count);
  }
  EXPECT_EQ(sorted[0], sorted[1]);
  EXPECT_EQ(permutation[0], permutation[1]);
  EXPECT_EQ(scanned[0], scanned[1]);
  EXPECT_EQ(sums[0], sums[1]);
  EXPECT_EQ(uniques[0], uniques[1]);
}

TEST(DeviceSelection, ParsesRequestsAndRejectsUnknownNames) {
  EXPECT_EQ(parse_device_request("auto"), DeviceRequest::kAuto);
  EXPECT_EQ(parse_device_request("CPU"), DeviceRequest::kCpu);
  EXPECT_EQ(parse_device_request("cuda"), DeviceRequest::kCuda);
  EXPECT_THROW(parse_device_request("tpu"), Error);
  EXPECT_EQ(select_device(DeviceRequest::kCpu), Device::kCpu);
  const Device automatic = select_device(DeviceRequest::kAuto);
  EXPECT_EQ(automatic, cuda_device_available() ? Device::kCuda : Device::kCpu);
  if (!cuda_device_available()) {
    EXPECT_THROW(select_device(DeviceRequest::kCuda), NotAvailableError);
  }
}

}  // namespace
}  // namespace covox

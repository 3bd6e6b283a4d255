// The CPU twin groups a frame's visit records by block and sums them in dense per-block arrays
// (tsdf_group_updates_cpu.h) instead of sorting them. It must give what a stable sort by key and
// a left-to-right sum of each key's records give (the GPU path's definition), bit for bit: the
// reference here is std::stable_sort and a plain loop, on records with many repeats per voxel,
// negative voxel indices, and records to drop (zero weight, outside the box) mixed in.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "covoxslam/integrators/internal/tsdf_group_updates_cpu.h"

namespace covox {
namespace {

struct Record {
  uint32_t key;
  integrators::tsdf::DistanceUpdate update;
};

void expect_grouping_matches_sorted_sums(int32_t voxels_per_side, int64_t count) {
  const Index3D low(-40, -25, -7), high(30, 12, 20);
  const integrators::tsdf::FrameKeyCodec codec =
      integrators::tsdf::make_frame_key_codec(low, high, voxels_per_side);
  ASSERT_TRUE(integrators::tsdf::dense_grouping_fits(codec));
  ASSERT_LE(codec.key_bits, 32);
  std::mt19937 random(static_cast<uint32_t>(voxels_per_side * 1000 + count));
  // Few distinct voxels for many records, so that most voxels repeat.
  std::uniform_int_distribution<int32_t> x(low.x, low.x + 9), y(low.y, high.y), z(-3, 3);
  std::uniform_real_distribution<float> value(-1.0f, 1.0f);
  std::uniform_int_distribution<int> kind(0, 19);
  std::vector<Record> records(static_cast<size_t>(count));
  for (Record& r : records) {
    const int k = kind(random);
    r.key = k == 0   ? static_cast<uint32_t>(codec.zero_weight_key)
            : k == 1 ? static_cast<uint32_t>(codec.out_of_range_key)
                     : static_cast<uint32_t>(codec.key(Index3D(x(random), y(random), z(random))));
    r.update.weighted_distance = value(random);
    r.update.weight = value(random) + 1.5f;
  }
  // Reference: stable sort, then each valid key's records summed left to right.
  std::vector<Record> sorted = records;
  std::stable_sort(sorted.begin(), sorted.end(),
                   [](const Record& a, const Record& b) { return a.key < b.key; });
  std::vector<uint32_t> expected_keys;
  std::vector<integrators::tsdf::DistanceUpdate> expected_sums;
  uint32_t zero_weight = 0, out_of_range = 0;
  for (const Record& r : sorted) {
    if (r.key == codec.zero_weight_key) {
      ++zero_weight;
    } else if (r.key == codec.out_of_range_key) {
      ++out_of_range;
    } else if (!expected_keys.empty() && expected_keys.back() == r.key) {
      expected_sums.back() = integrators::tsdf::MergeUpdates()(expected_sums.back(), r.update);
    } else {
      expected_keys.push_back(r.key);
      expected_sums.push_back(r.update);
    }
  }

  std::vector<uint32_t> keys(records.size()), keys_alt(records.size()), merged_keys(records.size());
  std::vector<integrators::tsdf::DistanceUpdate> values(records.size()), values_alt(records.size()),
      merged(records.size());
  for (size_t i = 0; i < records.size(); ++i) {
    keys[i] = records[i].key;
    values[i] = records[i].update;
  }
  const integrators::tsdf::DistanceUpdate* moved = values_alt.data();
  const integrators::tsdf::GroupCounts counts = integrators::tsdf::group_updates_by_voxel_cpu(
      codec, keys.data(), values.data(), count, keys_alt.data(), values_alt.data(),
      merged_keys.data(), merged.data(), [moved](int64_t j) { return moved[j]; },
      integrators::tsdf::MergeUpdates());

  ASSERT_EQ(counts.voxels, expected_keys.size());
  EXPECT_EQ(counts.zero_weight, zero_weight);
  EXPECT_EQ(counts.out_of_range, out_of_range);
  EXPECT_EQ(counts.runs, expected_keys.size() + (zero_weight > 0) + (out_of_range > 0));
  for (size_t v = 0; v < expected_keys.size(); ++v) {
    ASSERT_EQ(merged_keys[v], expected_keys[v]) << v;
    // Bit-identical: the same terms added in the same order.
    ASSERT_EQ(merged[v].weighted_distance, expected_sums[v].weighted_distance) << v;
    ASSERT_EQ(merged[v].weight, expected_sums[v].weight) << v;
  }
}

TEST(TsdfGroupUpdatesCpu, EqualsStableSortAndLeftToRightSums) {
  for (const int32_t side : {8, 16}) {
    for (const int64_t count : {int64_t(1), int64_t(1000), int64_t(200000)}) {
      SCOPED_TRACE("voxels per side " + std::to_string(side) + ", " + std::to_string(count) +
                   " records");
      expect_grouping_matches_sorted_sums(side, count);
    }
  }
}

}  // namespace
}  // namespace covox

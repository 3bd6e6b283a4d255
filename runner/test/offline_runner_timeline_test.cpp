// The offline runner's timeline table (runner/slam_run.h) reports nearest-rank percentiles of the
// scan times: they match the value a sorted copy holds at rank ceil(p n / 100), and are NaN for
// no values.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "runner/slam_run.h"

namespace covox {
namespace {

TEST(OfflineRunnerTimeline, NearestRankPercentilesMatchASortedReference) {
  std::vector<double> values;
  for (int k = 100; k >= 1; --k) values.push_back(static_cast<double>(k));
  std::mt19937 rng(5);
  std::shuffle(values.begin(), values.end(), rng);
  std::vector<double> copy = values;
  EXPECT_EQ(tools::nearest_rank_percentile(&copy, 50.0), 50.0);
  EXPECT_EQ(tools::nearest_rank_percentile(&copy, 95.0), 95.0);
  EXPECT_EQ(tools::nearest_rank_percentile(&copy, 100.0), 100.0);
  EXPECT_EQ(tools::nearest_rank_percentile(&copy, 0.5), 1.0);
  // Seven values: the nearest rank of p is ceil(p / 100 x 7) in sorted order.
  std::vector<double> seven = {0.7, 0.1, 0.5, 0.3, 0.2, 0.6, 0.4};
  std::vector<double> sorted = seven;
  std::sort(sorted.begin(), sorted.end());
  for (const double p : {10.0, 50.0, 95.0, 100.0}) {
    std::vector<double> work = seven;
    const size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * 7.0));
    EXPECT_EQ(tools::nearest_rank_percentile(&work, p), sorted[rank - 1]) << "p" << p;
  }
  std::vector<double> empty;
  EXPECT_TRUE(std::isnan(tools::nearest_rank_percentile(&empty, 50.0)));
}

}  // namespace
}  // namespace covox

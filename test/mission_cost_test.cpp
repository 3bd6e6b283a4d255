// What keeps a long mission's per-submap cost bounded, each against an independent reference:
//  * the overlap test on kept footprints counts the same shared blocks as a direct count over
//    the block lists, and as the test that exports the maps each time;
//  * the registration candidates of a new submap are at most overlap.max_partners, those sharing
//    most blocks, with and without kept footprints alike;
//  * the optimisation spacing keeps every n-th submap on small graphs, and bounds the summed
//    graph sizes solved per new submap (a solve's cost grows with the graph) on long missions.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <tuple>
#include <vector>

#include "covoxslam/backend/registration.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/tsdf_map.h"
#include "covoxslam/pipeline/registration_constraints.h"
#include "covoxslam/pipeline/slam_system.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using backend::Pose4Dof;
using BlockSet = std::set<std::tuple<int, int, int>>;

// A map with exactly `blocks` allocated (voxels untouched: the overlap test reads blocks only).
std::unique_ptr<map::TsdfMap> map_with_blocks(Device device, const BlockSet& blocks) {
  auto map = std::make_unique<map::TsdfMap>(device, map::TsdfMapConfig());
  std::vector<Index3D> keys;
  for (const auto& b : blocks) keys.emplace_back(std::get<0>(b), std::get<1>(b), std::get<2>(b));
  const Stream stream(device);
  auto device_keys = Buffer<Index3D>::from_host(device, keys);
  Buffer<uint32_t> slots(device, keys.size());
  map->blocks().activate(device_keys.data(), static_cast<int64_t>(keys.size()), slots.data(),
                         nullptr, stream);
  stream.synchronize();
  return map;
}

// A box of blocks with about a third of them left out at random, so footprints have holes.
BlockSet random_blocks(std::mt19937* rng, int origin_x, int size) {
  BlockSet blocks;
  std::uniform_int_distribution<int> keep(0, 2);
  for (int x = origin_x; x < origin_x + size; ++x)
    for (int y = -size / 2; y < size / 2; ++y)
      for (int z = 0; z < 3; ++z)
        if (keep(*rng) != 0) blocks.insert({x, y, z});
  if (blocks.empty()) blocks.insert({origin_x, 0, 0});
  return blocks;
}

// The reference: block centres of i moved through the two poses into j's block grid, counted
// when they land on a block of j's list. Written from the definition, on the lists given.
int64_t shared_blocks_reference(const BlockSet& blocks_i, const Pose4Dof& T_W_Si,
                                const BlockSet& blocks_j, const Pose4Dof& T_W_Sj, double block_m) {
  const Eigen::Isometry3d W_i = Eigen::Translation3d(T_W_Si.x, T_W_Si.y, T_W_Si.z) *
                                Eigen::AngleAxisd(T_W_Si.yaw, Eigen::Vector3d::UnitZ());
  const Eigen::Isometry3d W_j = Eigen::Translation3d(T_W_Sj.x, T_W_Sj.y, T_W_Sj.z) *
                                Eigen::AngleAxisd(T_W_Sj.yaw, Eigen::Vector3d::UnitZ());
  int64_t shared = 0;
  for (const auto& b : blocks_i) {
    const Eigen::Vector3d centre =
        (Eigen::Vector3d(std::get<0>(b), std::get<1>(b), std::get<2>(b)) +
         Eigen::Vector3d::Constant(0.5)) *
        block_m;
    const Eigen::Vector3d in_j = W_j.inverse() * (W_i * centre);
    const auto key = std::make_tuple(static_cast<int>(std::floor(in_j.x() / block_m)),
                                     static_cast<int>(std::floor(in_j.y() / block_m)),
                                     static_cast<int>(std::floor(in_j.z() / block_m)));
    shared += blocks_j.count(key);
  }
  return shared;
}

class MissionCostTest : public testing_support::DeviceTest {};

TEST_P(MissionCostTest, FootprintOverlapCountsTheSharedBlocks) {
  std::mt19937 rng(7);
  const BlockSet blocks_i = random_blocks(&rng, 0, 8), blocks_j = random_blocks(&rng, 3, 9);
  const auto map_i = map_with_blocks(device(), blocks_i);
  const auto map_j = map_with_blocks(device(), blocks_j);
  const backend::SubmapFootprint footprint_i = backend::submap_footprint(*map_i);
  const backend::SubmapFootprint footprint_j = backend::submap_footprint(*map_j);
  EXPECT_EQ(footprint_i.blocks.size(), blocks_i.size());
  EXPECT_EQ(footprint_i.keys.size(), blocks_i.size());
  const double block_m = map_i->block_size_m();
  std::uniform_real_distribution<double> offset(-4.0, 4.0), yaw(-3.0, 3.0);
  int overlapping = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const Pose4Dof T_W_Si{offset(rng), offset(rng), 0.3 * offset(rng), yaw(rng)};
    const Pose4Dof T_W_Sj{offset(rng), offset(rng), 0.3 * offset(rng), yaw(rng)};
    const backend::SubmapOverlap kept =
        backend::submap_overlap(footprint_i, T_W_Si, footprint_j, T_W_Sj, 4);
    const backend::SubmapOverlap exported =
        backend::submap_overlap(*map_i, T_W_Si, *map_j, T_W_Sj, 4);
    EXPECT_EQ(kept.shared_blocks, exported.shared_blocks) << "trial " << trial;
    EXPECT_EQ(kept.overlapping, exported.overlapping) << "trial " << trial;
    EXPECT_EQ(kept.bounding_boxes_intersect, exported.bounding_boxes_intersect);
    // The box test only skips pairs that share nothing.
    const int64_t reference = shared_blocks_reference(blocks_i, T_W_Si, blocks_j, T_W_Sj, block_m);
    EXPECT_EQ(kept.bounding_boxes_intersect ? kept.shared_blocks : 0, reference)
        << "trial " << trial;
    overlapping += kept.overlapping ? 1 : 0;
  }
  EXPECT_GT(overlapping, 5);  // the trials exercise the fine count, not only the box test
}

TEST_P(MissionCostTest, CandidatesAreTheBestOverlappingAtMostMaxPartners) {
  std::mt19937 rng(11);
  const BlockSet own_blocks = random_blocks(&rng, 0, 10);
  const auto own = map_with_blocks(device(), own_blocks);
  const Pose4Dof pose{0.5, -0.2, 0.0, 0.1};
  // Earlier submaps along a line: the farther, the fewer blocks they share with the new one.
  std::vector<BlockSet> blocks;
  std::vector<std::unique_ptr<map::TsdfMap>> maps;
  std::vector<backend::SubmapFootprint> footprints;
  for (int k = 0; k < 14; ++k) {
    blocks.push_back(random_blocks(&rng, k - 2, 10));
    maps.push_back(map_with_blocks(device(), blocks.back()));
    footprints.push_back(backend::submap_footprint(*maps.back()));
  }
  std::vector<pipeline::RegistrationPartner> plain, kept;
  for (size_t k = 0; k < maps.size(); ++k) {
    pipeline::RegistrationPartner partner;
    partner.id = static_cast<int64_t>(k);
    partner.map = maps[k].get();
    partner.pose = Pose4Dof{0.1 * k, 0.05 * k, 0.0, -0.02 * k};
    plain.push_back(partner);
    partner.footprint = &footprints[k];
    kept.push_back(partner);
  }
  pipeline::SubmapRegistrationConfig config;
  config.overlap.max_partners = 5;
  const double block_m = own->block_size_m();
  // The reference order: most shared blocks first, earlier submaps first among equals.
  std::vector<std::pair<int64_t, int64_t>> ranked;  // (-shared, id)
  for (size_t k = 0; k < maps.size(); ++k) {
    const int64_t shared =
        shared_blocks_reference(own_blocks, pose, blocks[k], plain[k].pose, block_m);
    if (shared >= config.overlap.min_shared_blocks)
      ranked.emplace_back(-shared, static_cast<int64_t>(k));
  }
  std::sort(ranked.begin(), ranked.end());
  ASSERT_GT(ranked.size(), 5u);  // more overlap than the bound lets through
  const auto chosen = pipeline::overlapping_partners(*own, pose, plain, config);
  const auto chosen_kept = pipeline::overlapping_partners(*own, pose, kept, config);
  ASSERT_EQ(chosen.size(), 5u);
  ASSERT_EQ(chosen_kept.size(), 5u);
  for (size_t k = 0; k < chosen.size(); ++k) {
    EXPECT_EQ(chosen[k]->id, ranked[k].second) << "rank " << k;
    EXPECT_EQ(chosen_kept[k]->id, ranked[k].second) << "rank " << k;
  }
}

TEST_P(MissionCostTest, MaxVisitsKeepsTheFirstAndTheLatestVisitsOfAPlace) {
  std::mt19937 rng(5);
  const BlockSet place = random_blocks(&rng, 0, 10);
  const auto own = map_with_blocks(device(), place);
  // Ten earlier submaps of the same place in four visits (ids more than min_id_gap apart), all
  // sharing every block with the new one.
  const std::vector<int64_t> ids = {0, 1, 2, 10, 11, 20, 21, 22, 30, 31};
  std::vector<std::unique_ptr<map::TsdfMap>> maps;
  std::vector<pipeline::RegistrationPartner> earlier;
  for (int64_t id : ids) {
    maps.push_back(map_with_blocks(device(), place));
    pipeline::RegistrationPartner partner;
    partner.id = id;
    partner.map = maps.back().get();
    earlier.push_back(partner);
  }
  pipeline::SubmapRegistrationConfig config;
  config.overlap.max_partners = 0;
  config.revisits.min_id_gap = 4;
  const auto chosen_ids = [&](int max_visits) {
    config.overlap.max_visits = max_visits;
    std::vector<int64_t> chosen;
    for (const auto* partner : pipeline::overlapping_partners(*own, Pose4Dof{}, earlier, config))
      chosen.push_back(partner->id);
    std::sort(chosen.begin(), chosen.end());
    return chosen;
  };
  EXPECT_EQ(chosen_ids(0), ids);
  EXPECT_EQ(chosen_ids(4), ids);
  EXPECT_EQ(chosen_ids(3), (std::vector<int64_t>{0, 1, 2, 20, 21, 22, 30, 31}));
  EXPECT_EQ(chosen_ids(2), (std::vector<int64_t>{0, 1, 2, 30, 31}));
  // The visit limit comes first, then max_partners among what is left (ties: lower ids first).
  config.overlap.max_partners = 4;
  EXPECT_EQ(chosen_ids(2), (std::vector<int64_t>{0, 1, 2, 30}));
  config.overlap.max_visits = 1;
  EXPECT_THROW(pipeline::validate(config), Error);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(MissionCostTest);

TEST(OptimisationSpacing, EveryNthOnSmallGraphsBoundedSolveWorkOnLongMissions) {
  pipeline::SlamConfig config;
  config.optimize_every_n_submaps = 1;
  config.optimize_spacing_fraction = 1.0 / 32.0;
  for (int64_t n = 0; n < 64; ++n) EXPECT_EQ(pipeline::submaps_between_optimizations(config, n), 1);
  EXPECT_EQ(pipeline::submaps_between_optimizations(config, 64), 2);
  EXPECT_EQ(pipeline::submaps_between_optimizations(config, 720), 22);
  config.optimize_every_n_submaps = 3;
  EXPECT_EQ(pipeline::submaps_between_optimizations(config, 10), 3);
  EXPECT_EQ(pipeline::submaps_between_optimizations(config, 320), 10);
  config.optimize_every_n_submaps = 0;
  EXPECT_EQ(pipeline::submaps_between_optimizations(config, 320), 0);

  // The backend's rule replayed over a mission of 4000 submaps: the graph sizes solved, summed
  // (a whole-graph solve costs in proportion to the size), per new submap, stay below
  // 1 / fraction plus the first solves' share, while solving every submap grows with the mission.
  config.optimize_every_n_submaps = 1;
  int64_t last = 0, solved_sizes = 0, every_submap_sizes = 0;
  for (int64_t n = 1; n <= 4000; ++n) {
    every_submap_sizes += n;
    const int64_t spacing = pipeline::submaps_between_optimizations(config, n);
    if (n - last >= spacing) {
      solved_sizes += n;
      last = n;
    }
    if (n % 500 == 0) {
      const double per_submap = static_cast<double>(solved_sizes) / static_cast<double>(n);
      EXPECT_LT(per_submap, 2.0 * 32.0 + 32.0) << "after " << n << " submaps";
    }
  }
  EXPECT_GT(static_cast<double>(every_submap_sizes) / 4000.0, 1000.0);
}

}  // namespace
}  // namespace covox

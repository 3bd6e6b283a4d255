// The memory budget on a lap of the yard that revisits its start. A budget the run never reaches
// changes nothing against no budget at all. A small budget forces finished submaps out of memory
// (compact, then spilled to disk) and back for the revisits: the map saved at the end is the
// unbounded run's byte for byte, and the registrations and the trajectory differ from it only by
// what quantising the restored partners moves them.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "covoxslam/io/submap_codec.h"
#include "pipeline_test_scene.h"

namespace covox {
namespace pipeline {
namespace {

using namespace test_scene;

struct LapResult {
  std::vector<std::vector<uint8_t>> saved;  // write_submaps(), in order
  std::vector<int64_t> ids;
  std::vector<SubmapConstraint> constraints;
  std::vector<StampedPose> trajectory;
  SlamCounters counters;
  size_t slice_points = 0;
};

LapResult run_lap(const MemoryBudgetConfig& memory) {
  SlamConfig config = yard_config();
  config.memory = memory;
  const sim::World world = make_yard();
  const sim::LidarConfig lidar = small_lidar();
  Drift drift;
  drift.yaw_rate_rad_per_s = 0.002;
  drift.bias_m_per_s = Eigen::Vector3d(0.01, -0.005, 0.0);
  SlamSystem slam(config);
  // One lap of the 6 m circle (about 38 s at 1 m/s) and a bit more, so the last submaps revisit
  // the first ones.
  const double period_s = 0.4;
  for (int k = 0; k * period_s <= 44.0; ++k) {
    const double t = k * period_s;
    SimulatedScan s =
        simulate(world, lidar, t, circle_pose(t), drift.at(t), static_cast<uint64_t>(k + 1));
    EXPECT_TRUE(slam.add_scan(std::move(s.scan)));
  }
  slam.finish();
  LapResult result;
  result.slice_points = slam.esdf_slice_world(1.0).size();
  slam.write_submaps([&](int64_t id, const Eigen::Isometry3d&, const std::vector<uint8_t>& bytes) {
    result.ids.push_back(id);
    result.saved.push_back(bytes);
  });
  result.constraints = slam.constraints();
  result.trajectory = slam.corrected_trajectory();
  result.counters = slam.counters();
  return result;
}

// `tolerance_m`: how far constraint translations and trajectory positions (m) and yaws (rad) may
// differ; 0: bit for bit.
void expect_same_run(const LapResult& a, const LapResult& b, double tolerance_m) {
  EXPECT_EQ(a.ids, b.ids);
  ASSERT_EQ(a.saved.size(), b.saved.size());
  for (size_t k = 0; k < a.saved.size(); ++k) EXPECT_TRUE(a.saved[k] == b.saved[k]) << k;
  ASSERT_EQ(a.constraints.size(), b.constraints.size());
  double worst_constraint = 0.0, worst_position = 0.0;
  for (size_t k = 0; k < a.constraints.size(); ++k) {
    const SubmapConstraint& x = a.constraints[k];
    const SubmapConstraint& y = b.constraints[k];
    EXPECT_EQ(x.kind, y.kind);
    EXPECT_EQ(x.from_submap, y.from_submap);
    EXPECT_EQ(x.to_submap, y.to_submap);
    const double differences[] = {
        x.measurement.x - y.measurement.x, x.measurement.y - y.measurement.y,
        x.measurement.z - y.measurement.z, x.measurement.yaw - y.measurement.yaw};
    for (double d : differences) worst_constraint = std::max(worst_constraint, std::abs(d));
    if (tolerance_m == 0.0) EXPECT_EQ(x.information, y.information);
  }
  ASSERT_EQ(a.trajectory.size(), b.trajectory.size());
  for (size_t k = 0; k < a.trajectory.size(); ++k) {
    const Eigen::Isometry3d& p = a.trajectory[k].T_world_sensor;
    const Eigen::Isometry3d& q = b.trajectory[k].T_world_sensor;
    worst_position = std::max(worst_position, (p.translation() - q.translation()).norm());
    if (tolerance_m == 0.0) EXPECT_EQ(p.matrix(), q.matrix());
  }
  std::cout << "largest differences: constraint " << worst_constraint << ", position "
            << worst_position << "\n";
  EXPECT_LE(worst_constraint, tolerance_m);
  EXPECT_LE(worst_position, tolerance_m);
  EXPECT_EQ(a.slice_points, b.slice_points);
}

MemoryBudgetConfig unbounded_budget() {
  MemoryBudgetConfig unbounded;
  unbounded.device_budget_mb = 1e6;
  unbounded.host_budget_mb = 1e6;
  return unbounded;
}

TEST(SubmapStore, ABudgetNeverReachedChangesNothing) {
  MemoryBudgetConfig none;
  none.device_budget_mb = 0.0;  // no store at all
  const LapResult reference = run_lap(none);
  const LapResult unbounded = run_lap(unbounded_budget());
  EXPECT_EQ(unbounded.counters.memory.compactions, 0);
  EXPECT_EQ(unbounded.counters.memory.compact_bytes, 0);
  EXPECT_GT(unbounded.counters.registration.accepted, 0);
  expect_same_run(unbounded, reference, 0.0);
}

TEST(SubmapStore, SmallBudgetSpillsAndKeepsTheUnboundedRunsMapAndRegistrations) {
  const LapResult reference = run_lap(unbounded_budget());

  MemoryBudgetConfig small;
  small.device_budget_mb = 1.0;  // one or two 8-voxel-block submaps of the yard
  small.host_budget_mb = 0.1;
  small.spill_directory = ::testing::TempDir();
  const LapResult bounded = run_lap(small);
  const SubmapStoreCounters& memory = bounded.counters.memory;
  std::cout << "resident " << memory.submaps_resident << " (" << memory.resident_bytes
            << " B), compact " << memory.submaps_compact << " (" << memory.compact_bytes
            << " B), on disk " << memory.submaps_on_disk << " (" << memory.disk_bytes
            << " B); compactions " << memory.compactions << ", restores " << memory.restores << " ("
            << memory.restore_s << " s), spills " << memory.spills << ", reads "
            << memory.spill_reads << "\n";
  EXPECT_GT(memory.compactions, 0);
  EXPECT_GT(memory.spills, 0);
  EXPECT_GT(memory.restores, 0);
  EXPECT_GT(memory.spill_reads, 0);
  EXPECT_EQ(memory.spill_failures, 0);
  EXPECT_LE(memory.resident_bytes, static_cast<int64_t>(1.0 * 1024 * 1024) + 600000);
  EXPECT_EQ(memory.submaps_resident + memory.submaps_compact + memory.submaps_on_disk,
            static_cast<int64_t>(bounded.ids.size()));
  // Quantised distances are within truncation / 2^15 of the originals and weights within 2^-11
  // of theirs: a restored partner moves an alignment by far less than a millimetre.
  expect_same_run(bounded, reference, 1e-3);
}

// A submap of `blocks` observed blocks of 8^3 voxels on the CPU.
std::unique_ptr<Submap> submap_of_blocks(int64_t id, int blocks) {
  map::TsdfMapConfig config;
  config.voxels_per_side = 8;
  auto submap = std::make_unique<Submap>(id, Device::kCpu, config, Eigen::Isometry3d::Identity());
  std::vector<map::HostBlock> host(static_cast<size_t>(blocks));
  for (int k = 0; k < blocks; ++k) {
    host[k].index = Index3D(k, 0, 0);
    host[k].tsdf.assign(512, map::TsdfVoxel{0.05f * (k + 1), 2.0f});
    host[k].color.assign(512, map::ColorVoxel{});
    host[k].esdf.assign(512, map::EsdfVoxel{});
  }
  submap->map().load_blocks(host, Stream());
  return submap;
}

TEST(SubmapStore, TheLeastRecentlyUsedSubmapLeavesFirst) {
  std::vector<std::unique_ptr<Submap>> submaps;
  for (int64_t id = 0; id < 3; ++id) submaps.push_back(submap_of_blocks(id, 4));
  const int64_t one_submap = voxel_pool_bytes(submaps[0]->map());
  ASSERT_GT(one_submap, 0);
  MemoryBudgetConfig budget;  // room for two of the three
  budget.device_budget_mb = 2.5 * static_cast<double>(one_submap) / (1024.0 * 1024.0);
  SubmapStore store(budget, 0.4f);
  std::vector<Submap*> graph_order;
  for (auto& submap : submaps) graph_order.push_back(submap.get());
  integrators::EsdfIntegrator esdf{integrators::EsdfIntegratorConfig{}};
  store.add(*submaps[0]);
  store.add(*submaps[1]);
  store.acquire(*submaps[0], esdf, Stream());  // submap 0 used again: 1 is now the least recent
  store.add(*submaps[2]);
  store.enforce(graph_order, -1);
  EXPECT_EQ(store.counters().compactions, 1);
  EXPECT_GT(submaps[0]->map().block_count(), 0);
  EXPECT_EQ(submaps[1]->map().block_count(), 0);
  EXPECT_GT(submaps[2]->map().block_count(), 0);
  // Back for a revisit, then 2 is the least recently used.
  store.acquire(*submaps[1], esdf, Stream());
  store.enforce(graph_order, -1);
  EXPECT_EQ(submaps[1]->map().block_count(), 4);
  EXPECT_EQ(submaps[2]->map().block_count(), 0);
}

TEST(SubmapStore, AFailedSpillKeepsTheSubmapInMemory) {
  MemoryBudgetConfig broken;
  broken.device_budget_mb = 1.0;
  broken.host_budget_mb = 0.0;
  broken.spill_directory = ::testing::TempDir() + "/no_such_folder_for_spills";
  const LapResult result = run_lap(broken);
  EXPECT_GT(result.counters.memory.spill_failures, 0);
  EXPECT_EQ(result.counters.memory.submaps_on_disk, 0);
  EXPECT_GT(result.counters.memory.submaps_compact, 0);
  for (const std::vector<uint8_t>& bytes : result.saved) {
    EXPECT_NO_THROW(io::validate_encoded_submap(bytes.data(), bytes.size(), "saved"));
  }
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

// The TSDF frame plan (internal/tsdf_frame_plan.h) decides each frame's path from the
// configuration, the frame strategy, the backend and the tally; some of the frame's named kernels
// run here alone on the CPU twin. References: the documented rules worked out by hand for a known
// box, and plain host loops.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <random>
#include <set>
#include <vector>

#include "covoxslam/core/parallel.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/internal/tsdf_frame_plan.h"
#include "covoxslam/integrators/internal/tsdf_stage_blocks.h"
#include "covoxslam/integrators/internal/tsdf_stage_point_rays.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace {

// A tally whose rays span voxels (0, 0, 0) to (79, 79, 79): with 8 voxels per side the codec's
// box is blocks -1 to 10 per axis, 12^3 = 1728 blocks of 512 cells.
constexpr uint64_t kBoxBlocks = 12 * 12 * 12;
constexpr uint64_t kBoxCells = kBoxBlocks * 512;

integrators::tsdf::FrameRays frame_rays(int64_t rays, int64_t visits) {
  integrators::tsdf::FrameRays frame;
  frame.count = rays;
  frame.tally.voxels = visits;
  for (int axis = 0; axis < 3; ++axis) {
    frame.tally.low[axis] = 0;
    frame.tally.high[axis] = 79;
  }
  return frame;
}

integrators::tsdf::TsdfFramePlan plan_of(Device backend,
                                         const integrators::tsdf::FrameStrategy& strategy,
                                         int budget_mb, bool colored, int64_t visits,
                                         int64_t last_listed_blocks = -1) {
  const map::TsdfMap map(Device::kCpu, map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegratorConfig config;  // truncation 0.6 m: 6 voxels
  config.fixed_point_sums_max_scratch_mb = budget_mb;
  integrators::tsdf::TsdfFramePlan plan;
  plan.has_color = colored;
  integrators::tsdf::plan_visits(&plan, config, strategy, backend, frame_rays(1000, visits), map,
                                 last_listed_blocks);
  return plan;
}

TEST(TsdfFramePlan, BoxFiguresFollowTheTally) {
  const integrators::tsdf::TsdfFramePlan plan =
      plan_of(Device::kCuda, integrators::tsdf::FrameStrategy{}, 512, true, int64_t(1) << 22);
  EXPECT_EQ(plan.box_blocks, static_cast<int64_t>(kBoxBlocks));
  EXPECT_EQ(plan.box_cells, kBoxCells);
  EXPECT_TRUE(plan.short_keys);  // the cells and the two drop keys are below 2^20
  EXPECT_TRUE(plan.marks_blocks);
  EXPECT_EQ(plan.cell_words, integrators::tsdf::kSumCellWords);
  // 1000 rays of at most floor(sqrt(3) (2 x 6 + 1)) + 6 = 28 band visits each.
  EXPECT_EQ(plan.band_bound, 28000);
  EXPECT_EQ(plan.piece_bound, (int64_t(1) << 22) / integrators::tsdf::kVoxelsPerPiece + 1000);
}

TEST(TsdfFramePlan, ShippedStrategySumsOnTheGpuWhenTheBudgetAllows) {
  const integrators::tsdf::FrameStrategy shipped;
  const int64_t many = int64_t(1) << 22, few = int64_t(1) << 19;
  // Every visit's cells: 48 bytes each with colour (42.5 MB), 16 without (14.2 MB).
  EXPECT_EQ(plan_of(Device::kCuda, shipped, 512, true, few).visits,
            integrators::tsdf::VisitMerging::kSumEveryVisit);
  EXPECT_EQ(plan_of(Device::kCuda, shipped, 40, true, many).visits,
            integrators::tsdf::VisitMerging::kSumFreeSpace);
  EXPECT_EQ(plan_of(Device::kCuda, shipped, 40, false, many).visits,
            integrators::tsdf::VisitMerging::kSumEveryVisit);
  // Free space alone (8 bytes a cell, 7.1 MB) only for frames of enough visits.
  EXPECT_EQ(plan_of(Device::kCuda, shipped, 40, true, few).visits,
            integrators::tsdf::VisitMerging::kSortEveryVisit);
  EXPECT_EQ(plan_of(Device::kCuda, shipped, 6, true, many).visits,
            integrators::tsdf::VisitMerging::kSortEveryVisit);
  EXPECT_EQ(plan_of(Device::kCuda, shipped, 0, false, many).visits,
            integrators::tsdf::VisitMerging::kSortEveryVisit);
  // The CPU twin never sums with the shipped strategy, and groups by block instead of sorting.
  const integrators::tsdf::TsdfFramePlan cpu = plan_of(Device::kCpu, shipped, 512, true, many);
  EXPECT_EQ(cpu.visits, integrators::tsdf::VisitMerging::kSortEveryVisit);
  EXPECT_TRUE(cpu.groups_on_cpu);
  EXPECT_FALSE(plan_of(Device::kCuda, shipped, 0, true, many).groups_on_cpu);
}

TEST(TsdfFramePlan, TestStrategiesReachEveryPath) {
  integrators::tsdf::FrameStrategy strategy;
  strategy.cpu_twin_sums_in_fixed_point = true;
  strategy.free_space_sums_min_visits = 0;
  const int64_t few = int64_t(1) << 19;
  const integrators::tsdf::TsdfFramePlan cpu = plan_of(Device::kCpu, strategy, 512, true, few);
  EXPECT_EQ(cpu.visits, integrators::tsdf::VisitMerging::kSumEveryVisit);
  EXPECT_FALSE(cpu.groups_on_cpu);
  EXPECT_EQ(plan_of(Device::kCpu, strategy, 40, true, few).visits,
            integrators::tsdf::VisitMerging::kSumFreeSpace);
  strategy.sum_band_in_fixed_point = false;
  EXPECT_EQ(plan_of(Device::kCuda, strategy, 512, true, few).visits,
            integrators::tsdf::VisitMerging::kSumFreeSpace);
  strategy.sum_free_space_in_fixed_point = false;
  EXPECT_EQ(plan_of(Device::kCuda, strategy, 512, true, few).visits,
            integrators::tsdf::VisitMerging::kSortEveryVisit);
}

TEST(TsdfFramePlan, SmallFramesDeferTheirBlockCount) {
  const integrators::tsdf::FrameStrategy shipped;
  const int64_t visits = int64_t(1) << 22;
  // Unknown last frame: wait. 2^21 cells = 4096 blocks of 512: defer up to there.
  EXPECT_FALSE(plan_of(Device::kCuda, shipped, 512, true, visits, -1).defers_block_count);
  EXPECT_TRUE(plan_of(Device::kCuda, shipped, 512, true, visits, 4096).defers_block_count);
  EXPECT_FALSE(plan_of(Device::kCuda, shipped, 512, true, visits, 4097).defers_block_count);
  // Only a frame that sums every visit activates while listing, so only it defers.
  EXPECT_FALSE(plan_of(Device::kCuda, shipped, 6, true, visits, 10).defers_block_count);
}

TEST(TsdfFramePlan, LargeBoxesAreMarkedOnlyWithAsManyVisits) {
  EXPECT_TRUE(integrators::tsdf::marks_blocks(int64_t(1) << 16, 10));
  EXPECT_FALSE(integrators::tsdf::marks_blocks((int64_t(1) << 16) + 1, 10));
  EXPECT_TRUE(integrators::tsdf::marks_blocks(int64_t(1) << 20, int64_t(1) << 20));
  EXPECT_FALSE(integrators::tsdf::marks_blocks(int64_t(1) << 31, int64_t(1) << 40));
}

// The scan of a box's marks lists each marked block at its rank, clears its mark and starts the
// frame's results with the count.
TEST(TsdfFrameKernels, ListMarkedBlockListsTheMarkedBlocksInBoxOrder) {
  const integrators::tsdf::FrameKeyCodec codec =
      integrators::tsdf::make_frame_key_codec(Index3D(-30, -20, -10), Index3D(40, 25, 33), 8);
  const int64_t box_blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  std::mt19937 random(7);
  std::vector<uint32_t> marks(static_cast<size_t>(box_blocks) + 1, 0u);
  std::vector<Index3D> expected;
  for (int64_t b = 0; b < box_blocks; ++b) {
    if (random() % 3 != 0) continue;
    marks[static_cast<size_t>(b)] = 1u;
    const int64_t plane = int64_t(codec.size_x) * codec.size_y;
    expected.push_back(
        Index3D(codec.origin_block.x + static_cast<int32_t>(b % codec.size_x),
                codec.origin_block.y + static_cast<int32_t>(b % plane / codec.size_x),
                codec.origin_block.z + static_cast<int32_t>(b / plane)));
  }
  std::vector<uint32_t> ranks(marks.size());
  std::vector<Index3D> listed(static_cast<size_t>(box_blocks));
  integrators::tsdf::FrameResults results{};
  results.zero_weight_first = 5u;
  const Stream stream(Device::kCpu);
  exclusive_scan_of(CpuBackend{}, stream, box_blocks + 1,
                    integrators::tsdf::IsMarkedBlock{marks.data()},
                    integrators::tsdf::ListMarkedBlock{ranks.data(), box_blocks, &results,
                                                       marks.data(), codec, listed.data(), false,
                                                       nullptr, map::BlockActivator{}, nullptr});
  ASSERT_EQ(results.blocks, expected.size());
  EXPECT_EQ(results.zero_weight_first, 0u);
  for (size_t k = 0; k < expected.size(); ++k) EXPECT_EQ(listed[k], expected[k]) << k;
  for (uint32_t mark : marks) EXPECT_EQ(mark, 0u);
  EXPECT_EQ(ranks.back(), expected.size());
}

// From sorted keys: one listed block per distinct block part of the kept keys (those below the
// out-of-range key), in key order.
TEST(TsdfFrameKernels, SortedRecordsListTheirDistinctBlocks) {
  const integrators::tsdf::FrameKeyCodec codec =
      integrators::tsdf::make_frame_key_codec(Index3D(-30, -20, -10), Index3D(40, 25, 33), 8);
  std::mt19937 random(11);
  std::uniform_int_distribution<int32_t> x(-30, 40), y(-20, 25), z(-10, 33);
  std::vector<uint32_t> keys;
  for (int k = 0; k < 3000; ++k)
    keys.push_back(static_cast<uint32_t>(codec.key(Index3D(x(random), y(random), z(random)))));
  std::sort(keys.begin(), keys.end());
  for (int k = 0; k < 5; ++k) keys.push_back(static_cast<uint32_t>(codec.out_of_range_key));
  keys.push_back(static_cast<uint32_t>(codec.zero_weight_key));
  std::vector<Index3D> expected;
  std::set<uint64_t> seen;
  for (uint32_t key : keys) {
    if (key >= codec.out_of_range_key || !seen.insert(codec.block_part(key)).second) continue;
    expected.push_back(codec.block(key));
  }
  const int64_t count = static_cast<int64_t>(keys.size());
  std::vector<uint32_t> flags(keys.size() + 1), ranks(keys.size() + 1);
  std::vector<Index3D> listed(keys.size());
  integrators::tsdf::FrameResults results{};
  const Stream stream(Device::kCpu);
  parallel_for(
      CpuBackend{}, stream, count + 1,
      integrators::tsdf::FlagBlockStarts<uint32_t>{
          keys.data(), count, static_cast<uint32_t>(codec.out_of_range_key), codec, flags.data()});
  exclusive_scan(CpuBackend{}, stream, static_cast<const uint32_t*>(flags.data()), count + 1,
                 ranks.data());
  parallel_for(CpuBackend{}, stream, count + 1,
               integrators::tsdf::ListSortedBlocks<uint32_t>{
                   flags.data(), ranks.data(), keys.data(), count, codec, listed.data(), &results});
  ASSERT_EQ(results.blocks, expected.size());
  for (size_t k = 0; k < expected.size(); ++k) EXPECT_EQ(listed[k], expected[k]) << k;
}

// The simple method's rays: each point's ray as make_ray makes it, its piece count, and a zero
// after the last for the scan.
TEST(TsdfFrameKernels, WritePointRaysWritesEachPointsRay) {
  integrators::tsdf::RayParameters parameters{Transform3f{}, 0.1f, 0.3f, 0.2f, 5.0f, true, true};
  const std::vector<Vec3f> points = {Vec3f(1.0f, 2.0f, 0.5f), Vec3f(0.0f, 0.0f, 0.0f),
                                     Vec3f(9.0f, -1.0f, 0.0f), Vec3f(0.05f, 0.0f, 0.0f)};
  const int64_t n = static_cast<int64_t>(points.size());
  std::vector<integrators::tsdf::RaySegment> rays(points.size());
  std::vector<uint32_t> pieces(points.size() + 1, 77u);
  parallel_for(CpuBackend{}, Stream(Device::kCpu), n + 1,
               integrators::tsdf::WritePointRays{parameters, 10.0f, points.data(), n, rays.data(),
                                                 pieces.data()});
  for (size_t i = 0; i < points.size(); ++i) {
    const integrators::tsdf::RaySegment ray = integrators::tsdf::make_ray(parameters, points[i]);
    EXPECT_EQ(rays[i].kind, ray.kind) << i;
    // A ray's voxels from its start voxel to its end voxel, one step per crossed grid line.
    uint32_t voxels = 0;
    if (ray.kind <= integrators::tsdf::kClearingRay) {
      EXPECT_EQ(rays[i].end.x, ray.end.x) << i;
      EXPECT_EQ(rays[i].start.y, ray.start.y) << i;
      const Index3D a = integrators::tsdf::voxel_of(ray.start, 10.0f),
                    b = integrators::tsdf::voxel_of(ray.end, 10.0f);
      voxels = 1u + static_cast<uint32_t>(std::abs(b.x - a.x) + std::abs(b.y - a.y) +
                                          std::abs(b.z - a.z));
    }
    EXPECT_EQ(pieces[i], (voxels + integrators::tsdf::kVoxelsPerPiece - 1) /
                             integrators::tsdf::kVoxelsPerPiece)
        << i;
  }
  EXPECT_EQ(pieces[points.size()], 0u);
  EXPECT_EQ(rays[0].kind, integrators::tsdf::kSurfaceRay);
  EXPECT_EQ(rays[1].kind, integrators::tsdf::kDroppedZero);
  EXPECT_EQ(rays[2].kind, integrators::tsdf::kClearingRay);
  EXPECT_EQ(rays[3].kind, integrators::tsdf::kDroppedTooClose);
  EXPECT_GT(pieces[0], 1u);
}

}  // namespace
}  // namespace covox

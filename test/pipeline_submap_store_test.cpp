// The memory budget on a lap of the yard that revisits its start. A budget the run never reaches
// changes nothing against no budget at all. A small budget forces finished submaps out of memory
// (compact, then spilled to disk) and back for the revisits: the map saved at the end is the
// unbounded run's byte for byte, the submaps' meshes are its meshes to within their encoding's
// grid, and the registrations and the trajectory differ from it only by what quantising the
// restored partners moves them.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <memory>
#include <string>
#include <utility>
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
  std::vector<map::Mesh> meshes;  // submap_mesh() of each id, in the submap's frame
  size_t combined_triangles = 0;
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
  for (int64_t id : result.ids) {
    map::Mesh mesh;
    Eigen::Isometry3d T_world_submap;
    EXPECT_TRUE(slam.submap_mesh(id, &mesh, &T_world_submap)) << id;
    result.meshes.push_back(std::move(mesh));
  }
  result.combined_triangles = slam.combined_mesh().triangle_count();
  result.constraints = slam.constraints();
  result.trajectory = slam.corrected_trajectory();
  result.counters = slam.counters();
  return result;
}

// The largest differences between two runs of the same scans: constraint measurements (x, y, z
// in m, yaw in rad) and trajectory positions (m).
struct RunDifferences {
  double constraint = 0.0;
  double position = 0.0;
};

// The runs saved the same map and kept the same constraints between the same submaps; returns how
// far their measurements and trajectories differ.
RunDifferences compare_runs(const LapResult& a, const LapResult& b) {
  RunDifferences worst;
  EXPECT_EQ(a.ids, b.ids);
  EXPECT_EQ(a.saved.size(), b.saved.size());
  for (size_t k = 0; k < std::min(a.saved.size(), b.saved.size()); ++k)
    EXPECT_TRUE(a.saved[k] == b.saved[k]) << k;
  EXPECT_EQ(a.constraints.size(), b.constraints.size());
  for (size_t k = 0; k < std::min(a.constraints.size(), b.constraints.size()); ++k) {
    const SubmapConstraint& x = a.constraints[k];
    const SubmapConstraint& y = b.constraints[k];
    EXPECT_EQ(x.kind, y.kind);
    EXPECT_EQ(x.from_submap, y.from_submap);
    EXPECT_EQ(x.to_submap, y.to_submap);
    const double differences[] = {
        x.measurement.x - y.measurement.x, x.measurement.y - y.measurement.y,
        x.measurement.z - y.measurement.z, x.measurement.yaw - y.measurement.yaw};
    for (double d : differences) worst.constraint = std::max(worst.constraint, std::abs(d));
  }
  EXPECT_EQ(a.trajectory.size(), b.trajectory.size());
  for (size_t k = 0; k < std::min(a.trajectory.size(), b.trajectory.size()); ++k) {
    const Eigen::Vector3d d =
        a.trajectory[k].T_world_sensor.translation() - b.trajectory[k].T_world_sensor.translation();
    worst.position = std::max(worst.position, d.norm());
  }
  return worst;
}

// RMS of the trajectory's distance from the truth (the odometry frame starts at the truth's).
double error_from_truth_m(const std::vector<StampedPose>& trajectory) {
  double sum = 0.0;
  for (const StampedPose& pose : trajectory)
    sum +=
        (pose.T_world_sensor.translation() - circle_pose(pose.stamp_s).translation()).squaredNorm();
  return trajectory.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(trajectory.size()));
}

// A mesh's triangles as the grid points (multiples of step_m) nearest their corners, each
// triangle starting at its smallest corner with its orientation kept, sorted: what stays of a
// mesh on its encoding's grid, whatever the order of its vertices (the mesher's global weld
// numbers vertices in the order its threads reach them).
std::vector<std::array<int64_t, 9>> triangles_on_grid(const map::Mesh& mesh, double step_m) {
  std::vector<std::array<int64_t, 9>> triangles;
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    std::array<std::array<int64_t, 3>, 3> corners;
    for (int c = 0; c < 3; ++c) {
      const Vec3f& v = mesh.vertices_m[mesh.triangles[3 * t + c]];
      corners[c] = {std::llround(v.x / step_m), std::llround(v.y / step_m),
                    std::llround(v.z / step_m)};
    }
    const auto first = std::min_element(corners.begin(), corners.end());
    std::rotate(corners.begin(), first, corners.end());
    std::array<int64_t, 9> key;
    for (int c = 0; c < 3; ++c)
      for (int axis = 0; axis < 3; ++axis) key[3 * c + axis] = corners[c][axis];
    triangles.push_back(key);
  }
  std::sort(triangles.begin(), triangles.end());
  return triangles;
}

// The runs' submap meshes (in each submap's frame, which depends only on its scans and
// odometry) have the same triangles on the grid of step_m.
void expect_same_meshes(const LapResult& a, const LapResult& b, double step_m) {
  ASSERT_EQ(a.meshes.size(), b.meshes.size());
  for (size_t k = 0; k < a.meshes.size(); ++k) {
    EXPECT_GT(a.meshes[k].triangle_count(), 0u) << k;
    EXPECT_EQ(a.meshes[k].vertices_m.size(), b.meshes[k].vertices_m.size()) << k;
    EXPECT_TRUE(triangles_on_grid(a.meshes[k], step_m) == triangles_on_grid(b.meshes[k], step_m))
        << "submap " << a.ids[k];
  }
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
  const RunDifferences differences = compare_runs(unbounded, reference);
  EXPECT_EQ(differences.constraint, 0.0);
  EXPECT_EQ(differences.position, 0.0);
  EXPECT_EQ(unbounded.slice_points, reference.slice_points);
  expect_same_meshes(unbounded, reference, yard_config().map.voxel_size_m / 256.0);
  EXPECT_GT(reference.combined_triangles, 0u);
  EXPECT_EQ(unbounded.combined_triangles, reference.combined_triangles);
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
            << memory.spill_reads << "; peak resident " << memory.peak_resident_bytes << " B\n";
  EXPECT_GT(memory.compactions, 0);
  EXPECT_GT(memory.spills, 0);
  EXPECT_GT(memory.restores, 0);
  EXPECT_GT(memory.spill_reads, 0);
  EXPECT_EQ(memory.spill_failures, 0);
  EXPECT_LE(memory.resident_bytes, static_cast<int64_t>(1.0 * 1024 * 1024) + 600000);
  EXPECT_EQ(memory.submaps_resident + memory.submaps_compact + memory.submaps_on_disk,
            static_cast<int64_t>(bounded.ids.size()));
  // A restored partner is the quantised submap with its ESDF recomputed: voxels at the surface
  // band's edge may change sides, which moves an alignment by a fraction of a voxel (0.2 m), and
  // the trajectory by less; it must stay as close to the truth as the unbounded run's.
  const RunDifferences differences = compare_runs(bounded, reference);
  const double bounded_error_m = error_from_truth_m(bounded.trajectory);
  const double reference_error_m = error_from_truth_m(reference.trajectory);
  std::cout << "largest differences: constraint " << differences.constraint << ", position "
            << differences.position << " m; error from the truth " << bounded_error_m
            << " m (unbounded " << reference_error_m << " m)\n";
  EXPECT_LE(differences.constraint, 0.1);
  EXPECT_LE(differences.position, 0.05);
  EXPECT_LE(bounded_error_m, reference_error_m + 0.01);
  EXPECT_NEAR(static_cast<double>(bounded.slice_points),
              static_cast<double>(reference.slice_points), 0.01 * reference.slice_points);
  // The meshes left with their submaps (encoded on a grid of 1/256 voxel, spilled, read back)
  // and came back as the meshes made, rounded to that grid.
  expect_same_meshes(bounded, reference, yard_config().map.voxel_size_m / 256.0);
  EXPECT_EQ(bounded.combined_triangles, reference.combined_triangles);
  EXPECT_EQ(memory.mesh_bytes, 0);  // every submap, its mesh with it, is in the spill file
  EXPECT_GT(reference.counters.memory.mesh_bytes, 0);
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
  const int64_t one_submap = submaps[0]->map().device_bytes();
  ASSERT_GT(one_submap, 0);
  MemoryBudgetConfig budget;  // room for two of the three
  budget.device_budget_mb = 2.5 * static_cast<double>(one_submap) / (1024.0 * 1024.0);
  SubmapStore store(budget, 0.4f, 0.001f);
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
  // 1 back for a revisit: 0 (used before 2 was added) is now the least recently used.
  store.acquire(*submaps[1], esdf, Stream());
  store.enforce(graph_order, -1);
  EXPECT_EQ(store.counters().compactions, 2);
  EXPECT_EQ(submaps[0]->map().block_count(), 0);
  EXPECT_EQ(submaps[1]->map().block_count(), 4);
  EXPECT_EQ(submaps[2]->map().block_count(), 4);
  // A sweep (a slice) brings 0 back without marking it used: it leaves first again, and the
  // resident 1 and 2 stay.
  store.acquire(*submaps[0], esdf, Stream(), /*mark_used=*/false);
  EXPECT_EQ(submaps[0]->map().block_count(), 4);
  store.enforce(graph_order, -1);
  EXPECT_EQ(store.counters().compactions, 3);
  EXPECT_EQ(submaps[0]->map().block_count(), 0);
  EXPECT_EQ(submaps[1]->map().block_count(), 4);
  EXPECT_EQ(submaps[2]->map().block_count(), 4);
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

// ESDF against an independent brute-force distance transform, incremental vs batch, CPU vs CUDA.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/map/tsdf_map.h"
#include "support/obstacle_scene.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::DeviceTest;
using testing_support::ObstacleScene;

constexpr float kVoxelSize = 0.1f;
constexpr float kMaxDistance = 0.5f;

struct ObservedVoxel {
  float tsdf;
  map::EsdfVoxel esdf;
};

std::map<Index3D, ObservedVoxel> observed_voxels(const map::TsdfMap& map, float min_weight) {
  std::map<Index3D, ObservedVoxel> voxels;
  const int side = map.voxels_per_side();
  for (const map::HostBlock& block : map.snapshot()) {
    for (int k = 0; k < side * side * side; ++k) {
      if (block.tsdf[k].weight < min_weight) continue;
      const Index3D global(block.index.x * side + k % side,
                           block.index.y * side + (k / side) % side,
                           block.index.z * side + k / (side * side));
      voxels[global] = {block.tsdf[k].distance_m, block.esdf[k]};
    }
  }
  return voxels;
}

// The reference: for every observed voxel, the distance to the nearest site found by checking
// every voxel within the maximum distance, signed by the TSDF, clamped like the ESDF.
// Returns the largest absolute difference to the ESDF.
double max_error_against_brute_force(const map::TsdfMap& map,
                                     const integrators::EsdfIntegratorConfig& config,
                                     int64_t* checked) {
  const auto voxels = observed_voxels(map, config.min_weight);
  const float site_threshold = config.site_distance_threshold_vox * map.voxel_size_m();
  std::map<Index3D, bool> sites;
  for (const auto& [index, voxel] : voxels) {
    if (std::abs(voxel.tsdf) <= site_threshold) sites[index] = true;
  }
  const int h = static_cast<int>(std::ceil(config.esdf_max_distance_m / map.voxel_size_m()));
  double worst = 0.0;
  *checked = 0;
  for (const auto& [index, voxel] : voxels) {
    double best = config.esdf_max_distance_m;
    for (int dz = -h; dz <= h; ++dz) {
      for (int dy = -h; dy <= h; ++dy) {
        for (int dx = -h; dx <= h; ++dx) {
          const double d = std::sqrt(double(dx * dx + dy * dy + dz * dz)) * map.voxel_size_m();
          if (d >= best) continue;
          if (sites.count(index + Index3D(dx, dy, dz))) best = d;
        }
      }
    }
    const double expected = voxel.tsdf < 0 ? -best : best;
    EXPECT_TRUE(voxel.esdf.observed) << "observed voxel not marked observed";
    worst = std::max(worst, std::abs(expected - voxel.esdf.distance_m));
    ++*checked;
  }
  return worst;
}

std::vector<Eigen::Isometry3d> poses_outside(const ObstacleScene& scene) {
  std::vector<Eigen::Isometry3d> poses;
  for (const Eigen::Vector3d& p :
       {Eigen::Vector3d(0.1, 0.05, 0.0), Eigen::Vector3d(-1.5, 1.0, 0.3),
        Eigen::Vector3d(1.6, -1.1, -0.2), Eigen::Vector3d(1.2, 1.3, 0.5)}) {
    if (scene.inside_obstacle(p)) continue;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = p;
    poses.push_back(pose);
  }
  return poses;
}

void integrate_scene(integrators::TsdfIntegrator& integrator, map::TsdfMap& map,
                     const ObstacleScene& scene, int repeats) {
  for (int r = 0; r < repeats; ++r) {
    for (const auto& pose : poses_outside(scene))
      integrator.integrate(map, scene.lidar(pose, 360, 90), {}, pose);
  }
}

integrators::TsdfIntegratorConfig tsdf_config() {
  integrators::TsdfIntegratorConfig config;
  config.truncation_distance_m = 3 * kVoxelSize;
  config.max_ray_length_m = 10.0f;
  config.use_const_weight = true;
  config.use_weight_dropoff = false;
  return config;
}

integrators::EsdfIntegratorConfig esdf_config() {
  integrators::EsdfIntegratorConfig config;
  config.esdf_max_distance_m = kMaxDistance;
  return config;
}

class EsdfIntegratorTest : public DeviceTest {};

TEST_P(EsdfIntegratorTest, MatchesBruteForceOnRandomObstacleScenes) {
  for (uint32_t seed : {1u, 2u}) {
    const ObstacleScene scene = ObstacleScene::random(seed, 4, 4);
    map::TsdfMap map(device(), map::TsdfMapConfig{kVoxelSize, 8, {}});
    integrators::TsdfIntegrator tsdf(tsdf_config());
    integrate_scene(tsdf, map, scene, 1);
    integrators::EsdfIntegrator esdf(esdf_config());
    const Stream stream(device());
    const integrators::EsdfUpdateStats stats = esdf.update(map, stream);
    EXPECT_EQ(stats.changed_blocks, map.block_count());
    int64_t checked = 0;
    EXPECT_LE(max_error_against_brute_force(map, esdf.config(), &checked), 1e-4) << "seed " << seed;
    EXPECT_GT(checked, 20000);
  }
}

TEST_P(EsdfIntegratorTest, IncrementalUpdatesEqualBatchAfterAddingAndRemovingObjects) {
  ObstacleScene empty_room;
  const ObstacleScene furnished = ObstacleScene::random(7, 3, 3);
  map::TsdfMap map(device(), map::TsdfMapConfig{kVoxelSize, 8, {}});
  integrators::TsdfIntegrator tsdf(tsdf_config());
  integrators::EsdfIntegrator esdf(esdf_config());
  const Stream stream(device());

  auto check_against_batch = [&](const char* stage) {
    const auto incremental = observed_voxels(map, esdf.config().min_weight);
    esdf.update_all(map, stream);
    const auto batch = observed_voxels(map, esdf.config().min_weight);
    ASSERT_EQ(incremental.size(), batch.size()) << stage;
    for (const auto& [index, voxel] : batch) {
      ASSERT_EQ(incremental.at(index).esdf.distance_m, voxel.esdf.distance_m) << stage;
    }
    int64_t checked = 0;
    EXPECT_LE(max_error_against_brute_force(map, esdf.config(), &checked), 1e-4) << stage;
  };

  integrate_scene(tsdf, map, empty_room, 1);
  esdf.update(map, stream);
  integrate_scene(tsdf, map, furnished, 2);  // objects appear: distances drop near them
  const integrators::EsdfUpdateStats added = esdf.update(map, stream);
  EXPECT_GT(added.changed_blocks, 0);
  check_against_batch("after adding objects");
  int sites_with_objects = 0;
  for (const auto& [index, voxel] : observed_voxels(map, 1e-4f))
    sites_with_objects += voxel.esdf.is_site;

  integrate_scene(tsdf, map, empty_room, 6);  // objects disappear: carving raises distances
  esdf.update(map, stream);
  check_against_batch("after removing objects");
  int sites_without_objects = 0;
  for (const auto& [index, voxel] : observed_voxels(map, 1e-4f))
    sites_without_objects += voxel.esdf.is_site;
  EXPECT_LT(sites_without_objects, sites_with_objects);

  // Nothing changed: nothing to do.
  EXPECT_EQ(esdf.update(map, stream).changed_blocks, 0);
}

TEST(EsdfIntegratorConfigCheck, RejectsBadParameters) {
  integrators::EsdfIntegratorConfig config;
  config.esdf_max_distance_m = 0.0f;
  EXPECT_THROW(integrators::EsdfIntegrator{config}, Error);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(EsdfIntegratorTest);

TEST(EsdfIntegratorParity, CpuAndCudaAgree) {
  COVOX_SKIP_WITHOUT_GPU();
  const ObstacleScene scene = ObstacleScene::random(3, 4, 4);
  std::vector<std::map<Index3D, ObservedVoxel>> results;
  for (Device device : {Device::kCpu, Device::kCuda}) {
    map::TsdfMap map(device, map::TsdfMapConfig{kVoxelSize, 8, {}});
    integrators::TsdfIntegrator tsdf(tsdf_config());
    integrate_scene(tsdf, map, scene, 1);
    integrators::EsdfIntegrator esdf(esdf_config());
    esdf.update(map, Stream(device));
    results.push_back(observed_voxels(map, 1e-4f));
  }
  ASSERT_EQ(results[0].size(), results[1].size());
  // The two TSDFs agree to 1e-4 m, so a voxel right at the site threshold may be a site on one
  // backend only; everywhere else the exact transform gives identical distances.
  int64_t identical = 0;
  for (const auto& [index, voxel] : results[0]) {
    const float other = results[1].at(index).esdf.distance_m;
    EXPECT_NEAR(voxel.esdf.distance_m, other, kVoxelSize);
    identical += voxel.esdf.distance_m == other;
  }
  EXPECT_GE(identical, static_cast<int64_t>(0.999 * results[0].size()));
}

}  // namespace
}  // namespace covox

// ESDF queries and slices against values read straight from the voxels on the host.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/esdf_queries.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "support/obstacle_scene.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::DeviceTest;
using testing_support::ObstacleScene;

constexpr float kVoxel = 0.1f;

class EsdfQueriesTest : public DeviceTest {
 protected:
  void SetUp() override {
    DeviceTest::SetUp();
    if (IsSkipped()) return;
    map_ = std::make_unique<map::TsdfMap>(device(), map::TsdfMapConfig{kVoxel, 8, {}});
    integrators::TsdfIntegratorConfig tsdf_config;
    tsdf_config.truncation_distance_m = 0.3f;
    tsdf_config.max_ray_length_m = 10.0f;
    integrators::TsdfIntegrator tsdf(tsdf_config);
    const ObstacleScene scene = ObstacleScene::random(5, 2, 2);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(0.05, 0.02, 0.01);
    tsdf.integrate(*map_, scene.lidar(pose, 360, 90), {}, pose);
    integrators::EsdfIntegratorConfig esdf_config;
    esdf_config.esdf_max_distance_m = 1.0f;
    integrators::EsdfIntegrator(esdf_config).update(*map_, Stream(device()));
    for (const map::HostBlock& block : map_->snapshot()) {
      for (int k = 0; k < 512; ++k) {
        if (!block.esdf[k].observed) continue;
        const Index3D v(block.index.x * 8 + k % 8, block.index.y * 8 + (k / 8) % 8,
                        block.index.z * 8 + k / 64);
        observed_[v] = block.esdf[k].distance_m;
      }
    }
  }
  std::unique_ptr<map::TsdfMap> map_;
  std::map<Index3D, float> observed_;
};

TEST_P(EsdfQueriesTest, TrilinearSamplesMatchVoxelsAtCentresAndInterpolateBetween) {
  std::vector<Vec3f> points;
  std::vector<float> expected;
  std::vector<Vec3f> expected_gradient;
  for (const auto& [v, d] : observed_) {
    // A point a quarter of the way from this voxel's centre to its +x+y+z neighbour's.
    bool all_observed = true;
    float corner[8];
    for (int c = 0; c < 8 && all_observed; ++c) {
      auto it = observed_.find(v + Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1));
      all_observed = it != observed_.end();
      if (all_observed) corner[c] = it->second;
    }
    if (!all_observed) continue;
    const float f = 0.25f;
    points.emplace_back((v.x + 0.5f + f) * kVoxel, (v.y + 0.5f + f) * kVoxel,
                        (v.z + 0.5f + f) * kVoxel);
    float value = 0.0f;
    Vec3f gradient;
    for (int c = 0; c < 8; ++c) {
      const float wx = (c & 1) ? f : 1 - f, wy = ((c >> 1) & 1) ? f : 1 - f,
                  wz = ((c >> 2) & 1) ? f : 1 - f;
      value += wx * wy * wz * corner[c];
      gradient.x += ((c & 1) ? 1.0f : -1.0f) * wy * wz * corner[c] / kVoxel;
      gradient.y += (((c >> 1) & 1) ? 1.0f : -1.0f) * wx * wz * corner[c] / kVoxel;
      gradient.z += (((c >> 2) & 1) ? 1.0f : -1.0f) * wx * wy * corner[c] / kVoxel;
    }
    expected.push_back(value);
    expected_gradient.push_back(gradient);
    if (points.size() >= 20000) break;
  }
  ASSERT_GT(points.size(), 1000u);
  const auto samples = integrators::query_esdf(*map_, points);
  for (size_t i = 0; i < points.size(); ++i) {
    ASSERT_TRUE(samples[i].valid);
    ASSERT_NEAR(samples[i].distance_m, expected[i], 1e-5f);
    ASSERT_NEAR(samples[i].gradient.x, expected_gradient[i].x, 1e-3f);
    ASSERT_NEAR(samples[i].gradient.y, expected_gradient[i].y, 1e-3f);
    ASSERT_NEAR(samples[i].gradient.z, expected_gradient[i].z, 1e-3f);
  }
  // Far outside the map: invalid.
  const auto outside = integrators::query_esdf(*map_, {Vec3f(500.0f, 500.0f, 500.0f)});
  EXPECT_FALSE(outside[0].valid);
}

TEST_P(EsdfQueriesTest, SlicesHoldTheLayerAndTheBandMinimum) {
  const float z = 0.27f;
  const int32_t layer = static_cast<int32_t>(std::floor(z / kVoxel));
  const auto slice = integrators::esdf_slice(*map_, z, Stream(device()));
  std::map<std::pair<int, int>, float> expected_layer, expected_band;
  for (const auto& [v, d] : observed_) {
    if (v.z == layer) expected_layer[{v.x, v.y}] = d;
    if (v.z >= -5 && v.z <= 4) {
      auto [it, inserted] = expected_band.emplace(std::make_pair(v.x, v.y), d);
      if (!inserted) it->second = std::min(it->second, d);
    }
  }
  ASSERT_EQ(slice.size(), expected_layer.size());
  for (const integrators::SlicePoint& p : slice) {
    const int x = static_cast<int>(std::floor(p.position_m.x / kVoxel));
    const int y = static_cast<int>(std::floor(p.position_m.y / kVoxel));
    ASSERT_EQ(p.distance_m, expected_layer.at({x, y}));
    ASSERT_NEAR(p.position_m.z, (layer + 0.5f) * kVoxel, 1e-6f);
  }
  const auto band = integrators::esdf_squashed_slice(*map_, -0.45f, 0.45f, Stream(device()));
  ASSERT_EQ(band.size(), expected_band.size());
  for (const integrators::SlicePoint& p : band) {
    const int x = static_cast<int>(std::floor(p.position_m.x / kVoxel));
    const int y = static_cast<int>(std::floor(p.position_m.y / kVoxel));
    ASSERT_EQ(p.distance_m, expected_band.at({x, y}));
  }
  EXPECT_THROW(integrators::esdf_squashed_slice(*map_, 1.0f, 0.0f, Stream(device())), Error);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(EsdfQueriesTest);

}  // namespace
}  // namespace covox

// Integrates one scan of a sphere seen from its centre into a TSDF map on the CPU backend and
// prints how many points went in and how many blocks were allocated. Exits non-zero when the
// integrator cast no ray or allocated no block.
#include <cmath>
#include <cstdio>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/map/tsdf_map.h"

int main() {
  constexpr float kVoxelSizeM = 0.1f;
  constexpr float kRadiusM = 2.0f;
  std::vector<covox::Vec3f> points;
  for (int i = 0; i < 64; ++i) {
    for (int j = 1; j < 32; ++j) {
      const float azimuth = 2.0f * static_cast<float>(M_PI) * static_cast<float>(i) / 64.0f;
      const float polar = static_cast<float>(M_PI) * static_cast<float>(j) / 32.0f;
      points.push_back(covox::Vec3f{kRadiusM * std::sin(polar) * std::cos(azimuth),
                                    kRadiusM * std::sin(polar) * std::sin(azimuth),
                                    kRadiusM * std::cos(polar)});
    }
  }
  covox::map::TsdfMap map(covox::Device::kCpu, covox::map::TsdfMapConfig{kVoxelSizeM, 8, {}});
  covox::integrators::TsdfIntegrator integrator(covox::integrators::TsdfIntegratorConfig{});
  const covox::integrators::IntegrationStats stats =
      integrator.integrate(map, points, {}, Eigen::Isometry3d::Identity());
  std::printf("downstream: %lld points integrated, %lld blocks allocated\n",
              static_cast<long long>(stats.points_in), static_cast<long long>(map.block_count()));
  return map.block_count() > 0 && stats.surface_rays > 0 ? 0 : 1;
}

#pragma once
// Fills a TsdfMap with an exact signed distance function sampled at voxel centres, so that
// mesh and ESDF tests can be checked independently of TSDF integration.
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <functional>
#include <set>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace testing_support {

// Allocates every block overlapping [min, max] (metres) and sets each voxel's distance to
// sdf(centre) (clamped to +-truncation), weight 1 and colour by position.
inline void fill_tsdf(map::TsdfMap& map, const Eigen::Vector3d& min, const Eigen::Vector3d& max,
                      float truncation_m,
                      const std::function<double(const Eigen::Vector3d&)>& sdf) {
  const double block = map.block_size_m();
  std::vector<Index3D> blocks;
  for (int x = int(std::floor(min.x() / block)); x <= int(std::floor(max.x() / block)); ++x) {
    for (int y = int(std::floor(min.y() / block)); y <= int(std::floor(max.y() / block)); ++y) {
      for (int z = int(std::floor(min.z() / block)); z <= int(std::floor(max.z() / block)); ++z) {
        blocks.emplace_back(x, y, z);
      }
    }
  }
  const Stream stream(map.device());
  auto keys = Buffer<Index3D>::from_host(map.device(), blocks);
  Buffer<uint32_t> slots(map.device(), blocks.size());
  map.blocks().activate(keys.data(), blocks.size(), slots.data(), nullptr, stream);
  map.ensure_pool_capacity(stream);
  const auto host_slots = slots.to_host();
  auto tsdf = map.tsdf().to_host();
  auto color = map.color().to_host();
  const int side = map.voxels_per_side();
  const double voxel = map.voxel_size_m();
  for (size_t b = 0; b < blocks.size(); ++b) {
    for (int k = 0; k < side * side * side; ++k) {
      const Eigen::Vector3d centre((blocks[b].x * side + k % side + 0.5) * voxel,
                                   (blocks[b].y * side + (k / side) % side + 0.5) * voxel,
                                   (blocks[b].z * side + k / (side * side) + 0.5) * voxel);
      const double d = std::max<double>(-truncation_m, std::min<double>(truncation_m, sdf(centre)));
      const size_t index = size_t(host_slots[b]) * side * side * side + k;
      tsdf[index] = map::TsdfVoxel{static_cast<float>(d), 1.0f};
      color[index] = map::ColorVoxel{uint8_t(100 + 10 * (k % 3)), 50, 200, 1.0f};
    }
  }
  map.tsdf().copy_from_host(tsdf, stream);
  map.color().copy_from_host(color, stream);
  map.block_changed().fill_bytes(map::kAllPending, stream);
  stream.synchronize();
}

}  // namespace testing_support
}  // namespace covox

// The SoA and AoS layouts behind one interface give identical results, on every backend.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <numeric>
#include <random>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/soa_container.h"
#include "covoxslam/map/voxel_pool_ops.h"
#include "covoxslam/map/voxels.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::DeviceTest;

std::vector<map::ColoredTsdfVoxel> random_voxels(size_t count, uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> distance(-0.3f, 0.3f), weight(0.0f, 20.0f);
  std::vector<map::ColoredTsdfVoxel> voxels(count);
  for (auto& v : voxels) {
    v.distance_m = distance(random);
    v.weight = weight(random);
    v.r = static_cast<uint8_t>(random());
    v.g = static_cast<uint8_t>(random());
    v.b = static_cast<uint8_t>(random());
    v.color_weight = weight(random);
  }
  return voxels;
}

bool same_bits(const map::ColoredTsdfVoxel& a, const map::ColoredTsdfVoxel& b) {
  return std::memcmp(&a.distance_m, &b.distance_m, 4) == 0 &&
         std::memcmp(&a.weight, &b.weight, 4) == 0 && a.r == b.r && a.g == b.g && a.b == b.b &&
         std::memcmp(&a.color_weight, &b.color_weight, 4) == 0;
}

template <Layout L>
struct LayoutRun {
  std::vector<map::ColoredTsdfVoxel> voxels_after_blend;
  std::vector<float> gathered;
};

template <Layout L>
LayoutRun<L> run_layout(Device device, const std::vector<map::ColoredTsdfVoxel>& initial,
                        const std::vector<uint32_t>& update_indices,
                        const std::vector<float>& update_distances,
                        const std::vector<float>& update_weights,
                        const std::vector<uint32_t>& query_indices) {
  Stream stream(device);
  VoxelStorage<map::ColoredTsdfVoxel, L> storage(device);
  storage.copy_from_host(initial);
  auto indices = Buffer<uint32_t>::from_host(device, update_indices);
  auto distances = Buffer<float>::from_host(device, update_distances);
  auto weights = Buffer<float>::from_host(device, update_weights);
  auto queries = Buffer<uint32_t>::from_host(device, query_indices);
  Buffer<float> gathered(device, query_indices.size());
  dispatch(device, [&](auto backend) {
    map::blend_tsdf_updates(backend, stream, storage.view(), indices.data(), distances.data(),
                            weights.data(), update_indices.size(), 50.0f);
    map::gather_voxel_distances(backend, stream, storage.view(), queries.data(),
                                query_indices.size(), gathered.data());
  });
  stream.synchronize();
  return {storage.to_host(), gathered.to_host()};
}

class VoxelLayoutTest : public DeviceTest {};

TEST_P(VoxelLayoutTest, SoaAndAosGiveIdenticalResults) {
  const size_t voxel_count = 4096 * 8;
  const auto initial = random_voxels(voxel_count, 1);
  std::vector<uint32_t> update_indices(voxel_count / 2);
  std::iota(update_indices.begin(), update_indices.end(), 0u);
  std::shuffle(update_indices.begin(), update_indices.end(), std::mt19937(2));
  for (auto& index : update_indices) index = index * 2 + 1;  // distinct, odd voxels only
  std::vector<float> distances(update_indices.size()), weights(update_indices.size());
  std::mt19937 random(3);
  for (size_t i = 0; i < distances.size(); ++i) {
    distances[i] = std::uniform_real_distribution<float>(-0.3f, 0.3f)(random);
    weights[i] = std::uniform_real_distribution<float>(0.0f, 40.0f)(random);
  }
  std::vector<uint32_t> queries(100000);
  for (auto& q : queries) q = random() % voxel_count;

  const auto soa =
      run_layout<Layout::kSoA>(device(), initial, update_indices, distances, weights, queries);
  const auto aos =
      run_layout<Layout::kAoS>(device(), initial, update_indices, distances, weights, queries);
  ASSERT_EQ(soa.voxels_after_blend.size(), aos.voxels_after_blend.size());
  for (size_t i = 0; i < voxel_count; ++i) {
    ASSERT_TRUE(same_bits(soa.voxels_after_blend[i], aos.voxels_after_blend[i])) << i;
  }
  EXPECT_EQ(soa.gathered, aos.gathered);

  // And against the arithmetic done here on the host.
  std::vector<map::ColoredTsdfVoxel> expected = initial;
  for (size_t i = 0; i < update_indices.size(); ++i) {
    auto& v = expected[update_indices[i]];
    const float combined = v.weight + weights[i];
    if (combined <= 0.0f) continue;
    v.distance_m = (v.distance_m * v.weight + distances[i] * weights[i]) / combined;
    v.weight = std::min(combined, 50.0f);
  }
  for (size_t i = 0; i < voxel_count; ++i) {
    ASSERT_NEAR(soa.voxels_after_blend[i].distance_m, expected[i].distance_m, 1e-6f) << i;
    ASSERT_FLOAT_EQ(soa.voxels_after_blend[i].weight, expected[i].weight) << i;
    ASSERT_EQ(soa.voxels_after_blend[i].r, expected[i].r);  // untouched fields stay
  }
  for (size_t q = 0; q < queries.size(); ++q) {
    ASSERT_EQ(soa.gathered[q], soa.voxels_after_blend[queries[q]].distance_m);
  }
}

TEST_P(VoxelLayoutTest, ResizeKeepsContentsAndZeroesNewVoxels) {
  const auto initial = random_voxels(1000, 5);
  VoxelStorage<map::ColoredTsdfVoxel, Layout::kSoA> soa(device());
  VoxelStorage<map::ColoredTsdfVoxel, Layout::kAoS> aos(device());
  soa.copy_from_host(initial);
  aos.copy_from_host(initial);
  soa.resize(2500);
  aos.resize(2500);
  const auto soa_host = soa.to_host();
  const auto aos_host = aos.to_host();
  const map::ColoredTsdfVoxel zero{};
  for (size_t i = 0; i < 2500; ++i) {
    const map::ColoredTsdfVoxel& expected = i < 1000 ? initial[i] : zero;
    ASSERT_TRUE(same_bits(soa_host[i], expected)) << i;
    ASSERT_TRUE(same_bits(aos_host[i], expected)) << i;
  }
  EXPECT_EQ(soa.bytes_per_voxel(), 4u + 4u + 1u + 1u + 1u + 4u);  // no padding in SoA
  EXPECT_EQ(aos.bytes_per_voxel(), sizeof(map::ColoredTsdfVoxel));
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(VoxelLayoutTest);

TEST(VoxelLayoutParity, CpuAndCudaBlendIdentically) {
  COVOX_SKIP_WITHOUT_GPU();
  const auto initial = random_voxels(20000, 9);
  std::vector<uint32_t> indices(10000);
  std::iota(indices.begin(), indices.end(), 5000u);
  std::vector<float> distances(indices.size(), 0.1f), weights(indices.size(), 2.0f);
  const std::vector<uint32_t> queries(indices.begin(), indices.end());
  const auto cpu =
      run_layout<Layout::kSoA>(Device::kCpu, initial, indices, distances, weights, queries);
  const auto gpu =
      run_layout<Layout::kSoA>(Device::kCuda, initial, indices, distances, weights, queries);
  for (size_t i = 0; i < initial.size(); ++i) {
    ASSERT_NEAR(cpu.voxels_after_blend[i].distance_m, gpu.voxels_after_blend[i].distance_m, 1e-6f);
    ASSERT_EQ(cpu.voxels_after_blend[i].weight, gpu.voxels_after_blend[i].weight);
  }
}

}  // namespace
}  // namespace covox

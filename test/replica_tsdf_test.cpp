// Real-data surface accuracy: the four Replica office0 depth frames (nvblox test data) are fused
// with their ground-truth poses into a 2 cm TSDF, meshed, and every mesh vertex is compared with
// the ground-truth mesh office0_mesh.ply by its exact distance to the nearest triangle. Replica
// renders are noise-free, so the error is what integration and marching cubes add: the median
// must stay below one voxel.
// Data: Replica research license (see the data folder's README.md).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "covoxslam/core/device.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/image_codecs.h"
#include "covoxslam/io/ply_reader.h"
#include "covoxslam/io/rgbd_folder.h"
#include "covoxslam/pipeline/mapper.h"
#include "eval/mesh_distance.h"

namespace covox {
namespace {

constexpr float kVoxelSizeM = 0.02f;
// Every second pixel in both directions: 600 x 340 rays per frame keep the CPU run to about a
// second while still giving several rays per 2 cm voxel at office distances.
constexpr int kPixelStride = 2;

double percentile(std::vector<double> values, double fraction) {
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(fraction * values.size()));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

// The `rgbd` preset's weighting at 2 cm, 4 voxels of truncation and 12 m rays.
pipeline::MapperConfig replica_config(Device device) {
  pipeline::MapperConfig config = pipeline::load_mapper_config({"rgbd"});
  config.device = device;
  config.map.voxel_size_m = kVoxelSizeM;
  config.map.voxels_per_side = 8;
  config.tsdf.truncation_distance_m = 4.0f * kVoxelSizeM;
  config.tsdf.max_ray_length_m = 12.0f;
  // Noise-free renders: only the band matters here, and carving the free space of 800k rays of
  // up to 10 m would cost most of the run time.
  config.tsdf.voxel_carving_enabled = false;
  config.tsdf.integrate_color = false;
  return config;
}

// Pixel (kPixelStride u, kPixelStride v) of the frame: a camera with focal lengths and principal
// point divided by the stride.
io::RgbdFrame every_other_pixel(const io::RgbdFrame& frame) {
  io::RgbdFrame subsampled;
  subsampled.T_world_camera = frame.T_world_camera;
  const int width = frame.depth.width / kPixelStride, height = frame.depth.height / kPixelStride;
  subsampled.intrinsics = io::CameraIntrinsics{frame.intrinsics.fx / kPixelStride,
                                               frame.intrinsics.fy / kPixelStride,
                                               frame.intrinsics.cx / kPixelStride,
                                               frame.intrinsics.cy / kPixelStride,
                                               width,
                                               height};
  subsampled.depth.width = width;
  subsampled.depth.height = height;
  subsampled.depth.depth_m.resize(static_cast<size_t>(width) * height);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u)
      subsampled.depth.depth_m[v * width + u] = frame.depth.at(v * kPixelStride, u * kPixelStride);
  }
  return subsampled;
}

void check_replica_surface_accuracy(Device device) {
  const std::string folder = io::data_directory() + "/nvblox-testdata/replica/office0";
  const std::string truth_path = io::data_directory() + "/nvblox-testdata/replica/office0_mesh.ply";
  if (!std::filesystem::exists(folder) || !std::filesystem::exists(truth_path)) {
    GTEST_SKIP() << "shared data not found at '" << folder << "' / '" << truth_path
                 << "' (set COVOX_DATA_DIR to the shared data folder)";
  }
  if (!io::png_reader_available()) GTEST_SKIP() << "built without libpng (install libpng-dev)";

  const io::RgbdFolder replica = io::RgbdFolder::open(folder);
  ASSERT_EQ(replica.size(), 4u);
  pipeline::Mapper mapper(replica_config(device));
  int64_t rays = 0;
  for (size_t index = 0; index < replica.size(); ++index) {
    rays += mapper.integrate_depth(every_other_pixel(replica.read_frame(index, nullptr, false)))
                .surface_rays;
  }
  const map::Mesh reconstructed = mapper.extract_mesh();
  ASSERT_GT(reconstructed.vertices_m.size(), 10000u);

  const map::Mesh truth = io::read_mesh_ply(truth_path);
  // 10 cm cells: a query meets a few dozen triangles of Replica's dense mesh, not thousands.
  const eval::MeshDistance truth_distance(truth, 0.1);
  constexpr double kFarM = 0.5;  // beyond this a vertex counts as "far" (no truth surface near)
  std::vector<double> distances_m;
  distances_m.reserve(reconstructed.vertices_m.size());
  size_t far = 0;
  for (const Vec3f& v : reconstructed.vertices_m) {
    const double distance_m = truth_distance.distance_m(Eigen::Vector3d(v.x, v.y, v.z), kFarM);
    far += !std::isfinite(distance_m);
    distances_m.push_back(std::isfinite(distance_m) ? distance_m : 1e9);
  }

  // Checks of the checker. The grid must agree with brute force over every triangle...
  for (size_t v = 0; v < reconstructed.vertices_m.size();
       v += reconstructed.vertices_m.size() / 100) {
    const Eigen::Vector3d p(reconstructed.vertices_m[v].x, reconstructed.vertices_m[v].y,
                            reconstructed.vertices_m[v].z);
    double brute_force_m = std::numeric_limits<double>::infinity();
    for (size_t t = 0; t < truth.triangle_count(); ++t) {
      const Vec3f& a = truth.vertices_m[truth.triangles[3 * t]];
      const Vec3f& b = truth.vertices_m[truth.triangles[3 * t + 1]];
      const Vec3f& c = truth.vertices_m[truth.triangles[3 * t + 2]];
      const Eigen::Vector3d closest = eval::closest_point_on_triangle(
          p, Eigen::Vector3d(a.x, a.y, a.z), Eigen::Vector3d(b.x, b.y, b.z),
          Eigen::Vector3d(c.x, c.y, c.z));
      brute_force_m = std::min(brute_force_m, (closest - p).norm());
    }
    // Beyond the search radius the grid answers "far" (stored as 1e9), whatever the true distance.
    if (brute_force_m > kFarM) {
      ASSERT_EQ(distances_m[v], 1e9)
          << "vertex " << v << " is " << brute_force_m << " m from the truth";
    } else {
      ASSERT_NEAR(distances_m[v], brute_force_m, 1e-12) << "vertex " << v;
    }
  }
  // ...and a mesh moved by 3 voxels diagonally (~3.5 cm along each axis) must fail the bound,
  // or the bound would not measure anything.
  std::vector<double> shifted_m;
  const Eigen::Vector3d shift = Eigen::Vector3d::Ones().normalized() * (3.0 * kVoxelSizeM);
  for (size_t v = 0; v < reconstructed.vertices_m.size(); v += 10) {
    const Vec3f& p = reconstructed.vertices_m[v];
    shifted_m.push_back(
        std::min(1e9, truth_distance.distance_m(Eigen::Vector3d(p.x, p.y, p.z) + shift, kFarM)));
  }
  const double shifted_median_m = percentile(shifted_m, 0.5);
  EXPECT_GT(shifted_median_m, kVoxelSizeM);
  size_t within_voxel = 0;
  for (double d : distances_m) within_voxel += d < kVoxelSizeM;
  const double median_m = percentile(distances_m, 0.5);
  const double p90_m = percentile(distances_m, 0.9);
  std::printf(
      "Replica office0 (%s): %lld rays, %zu mesh vertices, %zu triangles vs %zu ground-truth "
      "triangles: "
      "distance to truth median %.4f m, 90th percentile %.4f m, %.1f%% within one voxel, %zu "
      "beyond 0.5 m "
      "(mesh shifted by 6 cm: median %.4f m)\n",
      to_string(device), static_cast<long long>(rays), reconstructed.vertices_m.size(),
      reconstructed.triangle_count(), truth.triangle_count(), median_m, p90_m,
      100.0 * within_voxel / distances_m.size(), far, shifted_median_m);
  EXPECT_LT(median_m, kVoxelSizeM);
  EXPECT_LT(p90_m, 3.0 * kVoxelSizeM);
  EXPECT_LT(far, distances_m.size() / 100);
}

TEST(ReplicaTsdf, MeshMatchesGroundTruthWithinOneVoxelOnCpu) {
  check_replica_surface_accuracy(Device::kCpu);
}

TEST(ReplicaTsdf, MeshMatchesGroundTruthWithinOneVoxelOnCuda) {
  if (!cuda_device_available())
    GTEST_SKIP() << "no usable GPU on this machine: the CUDA run is on the GPU machine";
  check_replica_surface_accuracy(Device::kCuda);
}

}  // namespace
}  // namespace covox

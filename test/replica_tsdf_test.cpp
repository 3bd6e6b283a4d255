// Real-data surface accuracy: the four Replica office0 depth frames (nvblox test data) are fused
// with their ground-truth poses into a 2 cm TSDF, meshed, and every mesh vertex is compared with
// the ground-truth mesh office0_mesh.ply by its exact distance to the nearest triangle. Replica
// renders are noise-free, so the error is what integration and marching cubes add: the median
// must stay below one voxel.
// Data: Replica research license (see ../shared/data/README.md).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/image_codecs.h"
#include "covoxslam/io/ply_reader.h"
#include "covoxslam/io/rgbd_folder.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace {

constexpr float kVoxelSizeM = 0.02f;
// Every second pixel in both directions: 600 x 340 rays per frame keep the CPU run to about a
// second while still giving several rays per 2 cm voxel at office distances.
constexpr int kPixelStride = 2;

// Closest point on triangle (a, b, c) to p, by the Voronoi regions of its vertices, edges and
// face (Ericson, Real-Time Collision Detection, 5.1.5), in double precision.
Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  }
  const double denominator = 1.0 / (va + vb + vc);
  return a + ab * (vb * denominator) + ac * (vc * denominator);
}

// Exact point-to-mesh distance with a uniform grid: each triangle is listed in every cell it
// intersects (conservatively: cells whose centre lies within half a cell diagonal of it), and a
// query visits rings of cells around its own until the nearest triangle found is closer than
// anything in an unvisited ring can be.
class TriangleGrid {
 public:
  TriangleGrid(const Mesh& mesh, double cell_size_m) : cell_m_(cell_size_m) {
    for (const Vec3f& v : mesh.vertices_m) vertices_.emplace_back(v.x, v.y, v.z);
    const double half_diagonal_m = 0.5 * std::sqrt(3.0) * cell_m_;
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
      const Eigen::Vector3d& a = vertices_[mesh.triangles[3 * t]];
      const Eigen::Vector3d& b = vertices_[mesh.triangles[3 * t + 1]];
      const Eigen::Vector3d& c = vertices_[mesh.triangles[3 * t + 2]];
      triangles_.push_back({a, b, c});
      const Eigen::Array3i low = cell_of(a.cwiseMin(b).cwiseMin(c));
      const Eigen::Array3i high = cell_of(a.cwiseMax(b).cwiseMax(c));
      for (int z = low.z(); z <= high.z(); ++z) {
        for (int y = low.y(); y <= high.y(); ++y) {
          for (int x = low.x(); x <= high.x(); ++x) {
            const Eigen::Vector3d centre = (Eigen::Vector3d(x, y, z) + Eigen::Vector3d::Constant(0.5)) * cell_m_;
            if ((closest_point_on_triangle(centre, a, b, c) - centre).norm() <= half_diagonal_m) {
              cells_[key(x, y, z)].push_back(static_cast<uint32_t>(t));
            }
          }
        }
      }
    }
  }

  // Distance to the nearest triangle, or +infinity when none is within max_rings cells.
  double distance_m(const Eigen::Vector3d& p, int max_rings) const {
    const Eigen::Array3i home = cell_of(p);
    double best_m = std::numeric_limits<double>::infinity();
    for (int ring = 0; ring <= max_rings; ++ring) {
      for (int z = -ring; z <= ring; ++z) {
        for (int y = -ring; y <= ring; ++y) {
          for (int x = -ring; x <= ring; ++x) {
            if (std::max({std::abs(x), std::abs(y), std::abs(z)}) != ring) continue;  // shell only
            const auto cell = cells_.find(key(home.x() + x, home.y() + y, home.z() + z));
            if (cell == cells_.end()) continue;
            for (uint32_t t : cell->second) {
              const auto& [a, b, c] = triangles_[t];
              best_m = std::min(best_m, (closest_point_on_triangle(p, a, b, c) - p).norm());
            }
          }
        }
      }
      // Triangles not met yet miss the (2 ring + 1)^3 cells around p: they are at least
      // ring cells away.
      if (best_m <= ring * cell_m_) break;
    }
    return best_m;
  }

 private:
  struct Triangle {
    Eigen::Vector3d a, b, c;
  };

  Eigen::Array3i cell_of(const Eigen::Vector3d& p) const { return (p / cell_m_).array().floor().cast<int>(); }
  static int64_t key(int x, int y, int z) {
    return (int64_t(x) & 0x1fffff) | (int64_t(y) & 0x1fffff) << 21 | (int64_t(z) & 0x1fffff) << 42;
  }

  double cell_m_;
  std::vector<Eigen::Vector3d> vertices_;
  std::vector<Triangle> triangles_;
  std::unordered_map<int64_t, std::vector<uint32_t>> cells_;
};

double percentile(std::vector<double> values, double fraction) {
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(fraction * values.size()));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

void check_replica_surface_accuracy(Device device) {
  const std::string folder = io::data_directory() + "/nvblox-testdata/replica/office0";
  const std::string truth_path = io::data_directory() + "/nvblox-testdata/replica/office0_mesh.ply";
  if (!std::filesystem::exists(folder) || !std::filesystem::exists(truth_path)) {
    GTEST_SKIP() << "shared data not found at '" << folder << "' / '" << truth_path
                 << "' (set COVOX_DATA_DIR to the folder of ../shared/data/README.md)";
  }
  if (!io::png_reader_available()) GTEST_SKIP() << "built without libpng (install libpng-dev)";

  const io::RgbdFolder replica = io::RgbdFolder::open(folder);
  ASSERT_EQ(replica.size(), 4u);
  TsdfMap map(device, TsdfMapConfig{kVoxelSizeM, 8, {}});
  TsdfIntegratorConfig config;
  config.truncation_distance_m = 4.0f * kVoxelSizeM;
  config.max_ray_length_m = 12.0f;
  // Noise-free renders: only the band matters here, and carving the free space of 800k rays of
  // up to 10 m would cost most of the run time.
  config.voxel_carving_enabled = false;
  config.integrate_color = false;
  TsdfIntegrator integrator(config);
  const Stream stream(device);

  int64_t rays = 0;
  for (size_t index = 0; index < replica.size(); ++index) {
    const io::RgbdFrame frame = replica.read_frame(index, nullptr, false);
    // Subsampling pixel (stride u, stride v) is a camera with focal lengths and principal point
    // divided by the stride.
    const int width = frame.depth.width / kPixelStride, height = frame.depth.height / kPixelStride;
    std::vector<float> depth_m(static_cast<size_t>(width) * height);
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) depth_m[v * width + u] = frame.depth.at(v * kPixelStride, u * kPixelStride);
    }
    const Buffer<float> depth_device = Buffer<float>::from_host(device, depth_m);
    DepthImageView image;
    image.depth_m = depth_device.data();
    image.intrinsics = PinholeIntrinsics{float(frame.intrinsics.fx / kPixelStride), float(frame.intrinsics.fy / kPixelStride),
                                         float(frame.intrinsics.cx / kPixelStride), float(frame.intrinsics.cy / kPixelStride),
                                         width, height};
    const IntegrationStats stats = integrator.integrate_depth(map, image, frame.T_world_camera, stream);
    rays += stats.surface_rays;
  }

  MeshIntegrator mesher;
  const Mesh reconstructed = mesher.extract_all(map, stream);
  ASSERT_GT(reconstructed.vertices_m.size(), 10000u);

  const Mesh truth = io::read_mesh_ply(truth_path);
  const TriangleGrid grid(truth, 0.1);
  constexpr int kMaxRings = 5;  // beyond 0.5 m a vertex counts as "far" (no truth surface near)
  std::vector<double> distances_m;
  distances_m.reserve(reconstructed.vertices_m.size());
  size_t far = 0;
  for (const Vec3f& v : reconstructed.vertices_m) {
    const double distance_m = grid.distance_m(Eigen::Vector3d(v.x, v.y, v.z), kMaxRings);
    far += !std::isfinite(distance_m);
    distances_m.push_back(std::isfinite(distance_m) ? distance_m : 1e9);
  }

  // Checks of the checker. The grid must agree with brute force over every triangle...
  for (size_t v = 0; v < reconstructed.vertices_m.size(); v += reconstructed.vertices_m.size() / 100) {
    const Eigen::Vector3d p(reconstructed.vertices_m[v].x, reconstructed.vertices_m[v].y, reconstructed.vertices_m[v].z);
    double brute_force_m = std::numeric_limits<double>::infinity();
    for (size_t t = 0; t < truth.triangle_count(); ++t) {
      const Vec3f& a = truth.vertices_m[truth.triangles[3 * t]];
      const Vec3f& b = truth.vertices_m[truth.triangles[3 * t + 1]];
      const Vec3f& c = truth.vertices_m[truth.triangles[3 * t + 2]];
      brute_force_m = std::min(brute_force_m, (closest_point_on_triangle(p, Eigen::Vector3d(a.x, a.y, a.z),
                                                                         Eigen::Vector3d(b.x, b.y, b.z),
                                                                         Eigen::Vector3d(c.x, c.y, c.z)) - p).norm());
    }
    ASSERT_NEAR(distances_m[v], brute_force_m, 1e-12) << "vertex " << v;
  }
  // ...and a mesh moved by 3 voxels diagonally (~3.5 cm along each axis) must fail the bound,
  // or the bound would not measure anything.
  std::vector<double> shifted_m;
  const Eigen::Vector3d shift = Eigen::Vector3d::Ones().normalized() * (3.0 * kVoxelSizeM);
  for (size_t v = 0; v < reconstructed.vertices_m.size(); v += 10) {
    const Vec3f& p = reconstructed.vertices_m[v];
    shifted_m.push_back(std::min(1e9, grid.distance_m(Eigen::Vector3d(p.x, p.y, p.z) + shift, kMaxRings)));
  }
  const double shifted_median_m = percentile(shifted_m, 0.5);
  EXPECT_GT(shifted_median_m, kVoxelSizeM);
  size_t within_voxel = 0;
  for (double d : distances_m) within_voxel += d < kVoxelSizeM;
  const double median_m = percentile(distances_m, 0.5);
  const double p90_m = percentile(distances_m, 0.9);
  std::printf("Replica office0 (%s): %lld rays, %zu mesh vertices, %zu triangles vs %zu ground-truth triangles: "
              "distance to truth median %.4f m, 90th percentile %.4f m, %.1f%% within one voxel, %zu beyond 0.5 m "
              "(mesh shifted by 6 cm: median %.4f m)\n",
              to_string(device), static_cast<long long>(rays), reconstructed.vertices_m.size(),
              reconstructed.triangle_count(), truth.triangle_count(), median_m, p90_m,
              100.0 * within_voxel / distances_m.size(), far, shifted_median_m);
  EXPECT_LT(median_m, kVoxelSizeM);
  EXPECT_LT(p90_m, 3.0 * kVoxelSizeM);
  EXPECT_LT(far, distances_m.size() / 100);
}

TEST(ReplicaTsdf, MeshMatchesGroundTruthWithinOneVoxelOnCpu) { check_replica_surface_accuracy(Device::kCpu); }

TEST(ReplicaTsdf, MeshMatchesGroundTruthWithinOneVoxelOnCuda) {
  if (!cuda_device_available()) GTEST_SKIP() << "no usable GPU on this machine: the CUDA run is on the GPU machine";
  check_replica_surface_accuracy(Device::kCuda);
}

}  // namespace
}  // namespace covox

// TSDF raycast integration against analytic signed distances, weighting, colour, determinism,
// dropped input, and CPU vs CUDA parity.
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/integrators/internal/tsdf_frame_strategy.h"
#include "covoxslam/integrators/internal/tsdf_kernels.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/map/tsdf_map.h"
#include "support/analytic_scene.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::AnalyticScene;
using testing_support::DeviceTest;
using testing_support::Shape;

struct BandError {
  double rmse_voxels = 0.0;
  double zero_crossing_rmse_voxels = 0.0;
  int64_t zero_crossings = 0;
  int64_t band_voxels = 0;
  int64_t free_voxels = 0;
  int64_t free_voxels_not_positive = 0;
};

// Compares every observed voxel with the analytic SDF at its centre, and every zero crossing
// between two observed neighbouring voxels (where a mesh vertex would go) with the true surface.
BandError compare_with_scene(const map::TsdfMap& map, const AnalyticScene& scene,
                             float truncation_m) {
  BandError error;
  double squared = 0.0;
  const int side = map.voxels_per_side();
  const double voxel = map.voxel_size_m();
  const auto blocks = map.snapshot();
  std::map<Index3D, const map::TsdfVoxel*> by_voxel;
  for (const map::HostBlock& block : blocks) {
    for (int k = 0; k < side * side * side; ++k) {
      const Index3D global(block.index.x * side + k % side,
                           block.index.y * side + (k / side) % side,
                           block.index.z * side + k / (side * side));
      if (block.tsdf[k].weight > 0.0f) by_voxel[global] = &block.tsdf[k];
    }
  }
  double crossing_squared = 0.0;
  for (const auto& [index, v] : by_voxel) {
    for (const Index3D& step : {Index3D(1, 0, 0), Index3D(0, 1, 0), Index3D(0, 0, 1)}) {
      auto neighbour = by_voxel.find(index + step);
      if (neighbour == by_voxel.end()) continue;
      const float a = v->distance_m, b = neighbour->second->distance_m;
      // A sign change between two voxels that are both inside the band (not a free/occluded edge).
      if ((a > 0) == (b > 0) || std::abs(a) >= truncation_m || std::abs(b) >= truncation_m)
        continue;
      const double fraction = a / (a - b);
      const Eigen::Vector3d p = (Eigen::Vector3d(index.x + 0.5, index.y + 0.5, index.z + 0.5) +
                                 fraction * Eigen::Vector3d(step.x, step.y, step.z)) *
                                voxel;
      crossing_squared += scene.signed_distance(p) * scene.signed_distance(p);
      ++error.zero_crossings;
    }
  }
  error.zero_crossing_rmse_voxels =
      error.zero_crossings ? std::sqrt(crossing_squared / error.zero_crossings) / voxel : 0.0;
  for (const map::HostBlock& block : blocks) {
    for (int z = 0; z < side; ++z) {
      for (int y = 0; y < side; ++y) {
        for (int x = 0; x < side; ++x) {
          const map::TsdfVoxel& v = block.tsdf[x + side * (y + side * z)];
          if (v.weight <= 0.0f) continue;
          const Eigen::Vector3d center((block.index.x * side + x + 0.5) * voxel,
                                       (block.index.y * side + y + 0.5) * voxel,
                                       (block.index.z * side + z + 0.5) * voxel);
          const double truth = scene.signed_distance(center);
          if (std::abs(truth) < truncation_m) {
            squared += (v.distance_m - truth) * (v.distance_m - truth);
            ++error.band_voxels;
          } else if (truth > truncation_m + voxel) {
            ++error.free_voxels;
            if (!(v.distance_m > 0.0f)) ++error.free_voxels_not_positive;
          }
        }
      }
    }
  }
  error.rmse_voxels = error.band_voxels ? std::sqrt(squared / error.band_voxels) / voxel : 0.0;
  return error;
}

AnalyticScene make_scene(Shape shape) {
  AnalyticScene scene;
  scene.shape = shape;
  scene.center = Eigen::Vector3d(0.3, -0.2, shape == Shape::kPlane ? -1.5 : 0.1);
  scene.radius = 3.0;
  scene.half_extent = Eigen::Vector3d(3.0, 2.5, 2.0);
  return scene;
}

const char* shape_name(Shape shape) {
  return shape == Shape::kPlane ? "plane" : (shape == Shape::kSphere ? "sphere" : "box");
}

// A few viewpoints near the origin, so every band voxel is seen from several directions.
std::vector<Eigen::Isometry3d> viewpoints() {
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < 4; ++i) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() =
        Eigen::Vector3d(0.25 * std::cos(i * 1.7), 0.25 * std::sin(i * 1.7), 0.1 * i);
    pose.linear() = Eigen::AngleAxisd(0.4 * i, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                    Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitX()).toRotationMatrix();
    poses.push_back(pose);
  }
  return poses;
}

integrators::TsdfIntegratorConfig analytic_config(float voxel_size_m) {
  integrators::TsdfIntegratorConfig config;
  config.truncation_distance_m = 3.0f * voxel_size_m;
  config.max_ray_length_m = 10.0f;
  config.use_const_weight = false;
  return config;
}

class TsdfIntegratorTest : public DeviceTest {};

// The frame strategy that takes the fixed-point paths on both backends (the CPU twin's shipped
// strategy never does) and on the GPU for small frames too; `sum_free_space` and `sum_band` as
// tsdf::FrameStrategy has them.
integrators::tsdf::FrameStrategy summing_strategy(bool sum_free_space = true,
                                                  bool sum_band = true) {
  integrators::tsdf::FrameStrategy strategy;
  strategy.sum_free_space_in_fixed_point = sum_free_space;
  strategy.sum_band_in_fixed_point = sum_band;
  strategy.free_space_sums_min_visits = 0;
  strategy.cpu_twin_sums_in_fixed_point = true;
  return strategy;
}

// Raycast TSDFs store the distance along the ray, which exceeds the Euclidean distance by
// 1/cos(incidence): at grazing incidence the band cannot match the analytic SDF (a LiDAR over a
// ground plane gives about 1.1 voxel RMSE in the full band). So the band is checked with returns
// within kBandIncidenceDeg of the normal, and the zero crossings - the surface itself - with every
// return at any incidence.
constexpr double kBandIncidenceDeg = 25.0;

// One case of the analytic comparisons: integration method, scene, voxel size and the largest
// incidence angle of the simulated returns.
struct AnalyticCase {
  integrators::TsdfIntegrationMethod method;
  Shape shape;
  float voxel_size_m;
  double max_incidence_deg;
};

// Every combination, method outermost.
std::vector<AnalyticCase> analytic_cases() {
  std::vector<AnalyticCase> cases;
  for (integrators::TsdfIntegrationMethod method :
       {integrators::TsdfIntegrationMethod::kMerged, integrators::TsdfIntegrationMethod::kSimple}) {
    for (Shape shape : {Shape::kPlane, Shape::kSphere, Shape::kBox}) {
      for (float voxel_size : {0.05f, 0.1f, 0.2f}) {
        for (double max_incidence : {kBandIncidenceDeg, 90.0}) {
          cases.push_back(AnalyticCase{method, shape, voxel_size, max_incidence});
        }
      }
    }
  }
  return cases;
}

integrators::TsdfIntegratorConfig analytic_config(const AnalyticCase& c) {
  integrators::TsdfIntegratorConfig config = analytic_config(c.voxel_size_m);
  config.method = c.method;
  return config;
}

// How much of the scene a sensor's views must have reached; free voxels are checked only when
// free_voxels is positive.
struct CoverageMinimum {
  int64_t band_voxels;
  int64_t zero_crossings;
  int64_t free_voxels;
};

// The map of one case against the analytic SDF: the band within 0.3 voxel RMSE when the returns
// are near normal incidence, the zero crossings always, and no free voxel with a non-positive
// distance.
void expect_matches_scene(const map::TsdfMap& map, const AnalyticScene& scene,
                          const AnalyticCase& c, const CoverageMinimum& minimum) {
  const BandError error = compare_with_scene(map, scene, 3.0f * c.voxel_size_m);
  SCOPED_TRACE(std::string(to_string(c.method)) + " " + shape_name(c.shape) + " at " +
               std::to_string(c.voxel_size_m) + " m, incidence up to " +
               std::to_string(c.max_incidence_deg));
  EXPECT_GT(error.band_voxels, minimum.band_voxels);
  if (c.max_incidence_deg < 90.0) {
    EXPECT_LT(error.rmse_voxels, 0.3);
  }
  EXPECT_GT(error.zero_crossings, minimum.zero_crossings);
  EXPECT_LT(error.zero_crossing_rmse_voxels, 0.3);
  if (minimum.free_voxels > 0) {
    EXPECT_GT(error.free_voxels, minimum.free_voxels);
  }
  EXPECT_EQ(error.free_voxels_not_positive, 0);
}

TEST_P(TsdfIntegratorTest, SimulatedLidarMatchesAnalyticSdf) {
  for (const AnalyticCase& c : analytic_cases()) {
    const AnalyticScene scene = make_scene(c.shape);
    map::TsdfMap map(device(), map::TsdfMapConfig{c.voxel_size_m, 8, {}});
    integrators::TsdfIntegrator integrator(analytic_config(c));
    for (const auto& pose : viewpoints()) {
      // Tilt the spin axis for the ground plane, so that some beams look straight down.
      const Eigen::Isometry3d sensor =
          c.shape == Shape::kPlane ? pose * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX())
                                   : pose;
      const auto points =
          testing_support::simulate_lidar(scene, sensor, 720, 64, 90.0, 9.5, c.max_incidence_deg);
      const integrators::IntegrationStats stats = integrator.integrate(map, points, {}, sensor);
      ASSERT_EQ(stats.surface_rays, static_cast<int64_t>(points.size()));
    }
    expect_matches_scene(map, scene, c, CoverageMinimum{500, 100, 50});
  }
}

TEST_P(TsdfIntegratorTest, SimulatedDepthCameraMatchesAnalyticSdf) {
  const int width = 160, height = 120;
  const double f = 140.0;
  for (const AnalyticCase& c : analytic_cases()) {
    const AnalyticScene scene = make_scene(c.shape);
    map::TsdfMap map(device(), map::TsdfMapConfig{c.voxel_size_m, 8, {}});
    integrators::TsdfIntegrator integrator(analytic_config(c));
    const Stream stream(device());
    const auto viewpoints_list = viewpoints();
    for (const auto& pose : viewpoints_list) {
      // Look down for the plane, sideways into the sphere/room otherwise.
      Eigen::Isometry3d camera = pose;
      const Eigen::Vector3d turn_axis =
          c.shape == Shape::kPlane ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
      const double turn_angle = c.shape == Shape::kPlane ? M_PI : M_PI / 2;
      camera.linear() = pose.linear() * Eigen::Matrix3d(Eigen::AngleAxisd(turn_angle, turn_axis));
      const auto depth = testing_support::simulate_depth_mm(
          scene, camera, width, height, f, f, width / 2.0, height / 2.0, c.max_incidence_deg);
      auto depth_device = Buffer<uint16_t>::from_host(device(), depth);
      // Every other view passes metres instead of raw millimetres (both inputs are supported).
      std::vector<float> depth_metres(depth.size());
      for (size_t p = 0; p < depth.size(); ++p) depth_metres[p] = depth[p] * 1e-3f;
      auto depth_metres_device = Buffer<float>::from_host(device(), depth_metres);
      integrators::DepthImageView image;
      if (&pose - &viewpoints_list[0] == 1 || &pose - &viewpoints_list[0] == 3) {
        image.depth_m = depth_metres_device.data();
      } else {
        image.depth = depth_device.data();
      }
      image.intrinsics = integrators::PinholeIntrinsics{float(f),      float(f), width / 2.0f,
                                                        height / 2.0f, width,    height};
      image.depth_units_per_m = 1000.0f;
      image.invalid_value = 65535;
      integrator.integrate_depth(map, image, camera, stream);
    }
    expect_matches_scene(map, scene, c, CoverageMinimum{100, 20, 0});
  }
}

// One ray along +x hits a point at range 1.97 m: every voxel it crosses gets exactly one update, so
// the stored weight is the weighting function itself and the distance is the ray distance.
std::map<int, map::TsdfVoxel> single_ray_voxels(Device device,
                                                const integrators::TsdfIntegratorConfig& config) {
  map::TsdfMap map(device, map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegrator integrator(config);
  integrator.integrate(map, {Vec3f(1.97f, 0.05f, 0.05f)}, {}, Eigen::Isometry3d::Identity());
  std::map<int, map::TsdfVoxel> along_x;
  for (const map::HostBlock& block : map.snapshot()) {
    for (int x = 0; x < 8; ++x) {
      const map::TsdfVoxel& v = block.tsdf[x];  // y = z = 0 inside the block
      if (block.index.y == 0 && block.index.z == 0 && v.weight > 0.0f)
        along_x[block.index.x * 8 + x] = v;
    }
  }
  return along_x;
}

TEST_P(TsdfIntegratorTest, WeightingFunctionsFollowVoxbloxDefinitions) {
  integrators::TsdfIntegratorConfig config;
  config.truncation_distance_m = 0.4f;
  config.max_ray_length_m = 10.0f;
  config.min_ray_length_m = 0.0f;
  const double range = std::sqrt(1.97 * 1.97 + 2 * 0.05 * 0.05);

  config.use_const_weight = true;
  config.use_weight_dropoff = false;
  auto constant = single_ray_voxels(device(), config);
  ASSERT_EQ(constant.size(), 24u);  // voxels 0..23: origin to surface + truncation (2.37 m)
  for (const auto& [x, v] : constant) {
    EXPECT_FLOAT_EQ(v.weight, 1.0f) << x;
    const double expected = std::min(0.4, 1.97 - (x + 0.5) * 0.1);
    EXPECT_NEAR(v.distance_m, expected, 2e-3) << x;  // the ray is nearly along x
  }

  config.use_const_weight = false;  // inverse square of the range
  for (const auto& [x, v] : single_ray_voxels(device(), config)) {
    EXPECT_NEAR(v.weight, 1.0 / (range * range), 1e-6) << x;
  }

  config.use_const_weight = true;
  config.use_weight_dropoff = true;  // linear from -voxel to -truncation behind the surface
  for (const auto& [x, v] : single_ray_voxels(device(), config)) {
    const double sdf = 1.97 - (x + 0.5) * 0.1;
    const double expected = sdf < -0.1 ? (0.4 + sdf) / (0.4 - 0.1) : 1.0;
    EXPECT_NEAR(v.weight, expected, 2e-3) << x;
  }

  config.use_weight_dropoff = false;
  config.use_sparsity_compensation_factor = true;
  config.sparsity_compensation_factor = 20.0f;
  for (const auto& [x, v] : single_ray_voxels(device(), config)) {
    const double sdf = 1.97 - (x + 0.5) * 0.1;
    EXPECT_FLOAT_EQ(v.weight, std::abs(sdf) < 0.4 ? 20.0f : 1.0f) << x;
  }
}

// Every observed voxel of a map, by its block index and voxel-in-block position.
std::map<std::pair<Index3D, int>, map::TsdfVoxel> observed_voxels(const map::TsdfMap& map) {
  std::map<std::pair<Index3D, int>, map::TsdfVoxel> voxels;
  for (const map::HostBlock& block : map.snapshot()) {
    for (size_t v = 0; v < block.tsdf.size(); ++v) {
      if (block.tsdf[v].weight > 0.0f) voxels[{block.index, static_cast<int>(v)}] = block.tsdf[v];
    }
  }
  return voxels;
}

// The same blocks with the same TSDF voxels, bit for bit.
void expect_bit_identical_tsdf(const std::vector<map::HostBlock>& a,
                               const std::vector<map::HostBlock>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k) {
    ASSERT_EQ(a[k].index, b[k].index);
    ASSERT_EQ(0, std::memcmp(a[k].tsdf.data(), b[k].tsdf.data(),
                             a[k].tsdf.size() * sizeof(map::TsdfVoxel)))
        << "block " << k;
  }
}

// A scan of a sphere dense enough that most 0.1 m surface voxels hold several returns.
std::vector<Vec3f> dense_sphere_scan(const Eigen::Isometry3d& sensor) {
  const AnalyticScene scene = make_scene(Shape::kSphere);
  return testing_support::simulate_lidar(scene, sensor, 720, 64, 90.0, 9.5, 90.0);
}

// voxblox's merged integration: one ray per surface voxel, from the points' mean, with their
// summed weight. Checked against the simple integrator, which is its own independent path.
TEST_P(TsdfIntegratorTest, MergedRaysBundleThePointsOfOneVoxel) {
  const float voxel_size = 0.1f;
  integrators::TsdfIntegratorConfig simple = analytic_config(voxel_size);
  simple.method = integrators::TsdfIntegrationMethod::kSimple;
  simple.use_const_weight = true;
  simple.max_weight = 1e9f;  // no clamping: weights are compared as sums
  integrators::TsdfIntegratorConfig merged = simple;
  merged.method = integrators::TsdfIntegrationMethod::kMerged;
  const Eigen::Isometry3d sensor = viewpoints()[1];
  std::vector<Vec3f> points;  // those that become surface rays (inside the range limits)
  for (const Vec3f& p : dense_sphere_scan(sensor)) {
    const float range = p.norm();
    if (range >= simple.min_ray_length_m && range <= simple.max_ray_length_m) points.push_back(p);
  }

  // As many rays as distinct voxels holding a surface point (counted here on the host).
  std::set<Index3D> surface_voxels;
  for (const Vec3f& p : points) {
    const Eigen::Vector3d world = sensor * Eigen::Vector3d(p.x, p.y, p.z);
    surface_voxels.insert(Index3D(static_cast<int32_t>(std::floor(world.x() / voxel_size)),
                                  static_cast<int32_t>(std::floor(world.y() / voxel_size)),
                                  static_cast<int32_t>(std::floor(world.z() / voxel_size))));
  }
  {
    map::TsdfMap map(device(), map::TsdfMapConfig{voxel_size, 8, {}});
    const integrators::IntegrationStats stats =
        integrators::TsdfIntegrator(merged).integrate(map, points, {}, sensor);
    EXPECT_EQ(stats.surface_rays, static_cast<int64_t>(points.size()));
    // A point right on a voxel face may land on either side after the float transform.
    EXPECT_NEAR(static_cast<double>(stats.rays_cast), static_cast<double>(surface_voxels.size()),
                0.01 * surface_voxels.size());
    EXPECT_LT(stats.rays_cast, static_cast<int64_t>(points.size()) / 2);
  }

  // Each point three times: merged gives the simple map of the single cloud with three times the
  // weight, voxel for voxel (the mean of three equal points is the point).
  std::vector<Vec3f> tripled;
  for (const Vec3f& p : points) tripled.insert(tripled.end(), {p, p, p});
  std::vector<Vec3f> one_per_voxel;
  {
    std::set<Index3D> seen;
    for (const Vec3f& p : points) {
      const Eigen::Vector3d world = sensor * Eigen::Vector3d(p.x, p.y, p.z);
      const Index3D voxel(static_cast<int32_t>(std::floor(world.x() / voxel_size)),
                          static_cast<int32_t>(std::floor(world.y() / voxel_size)),
                          static_cast<int32_t>(std::floor(world.z() / voxel_size)));
      if (seen.insert(voxel).second) one_per_voxel.push_back(p);
    }
  }
  std::vector<Vec3f> one_tripled;
  for (const Vec3f& p : one_per_voxel) one_tripled.insert(one_tripled.end(), {p, p, p});
  map::TsdfMap merged_map(device(), map::TsdfMapConfig{voxel_size, 8, {}});
  map::TsdfMap simple_map(device(), map::TsdfMapConfig{voxel_size, 8, {}});
  integrators::TsdfIntegrator(merged).integrate(merged_map, one_tripled, {}, sensor);
  integrators::TsdfIntegrator(simple).integrate(simple_map, one_per_voxel, {}, sensor);
  const auto merged_voxels = observed_voxels(merged_map);
  const auto simple_voxels = observed_voxels(simple_map);
  ASSERT_EQ(merged_voxels.size(), simple_voxels.size());
  for (const auto& [key, voxel] : simple_voxels) {
    const auto found = merged_voxels.find(key);
    ASSERT_NE(found, merged_voxels.end());
    // Same updates, weights scaled by 3: only the rounding of the weighted averages differs.
    EXPECT_NEAR(found->second.distance_m, voxel.distance_m, 1e-4f);
    EXPECT_NEAR(found->second.weight, 3.0f * voxel.weight, 1e-5f * voxel.weight);
  }
}

TEST_P(TsdfIntegratorTest, ColorIsAveragedInsideTheBand) {
  integrators::TsdfIntegratorConfig config;
  config.truncation_distance_m = 0.3f;
  config.use_const_weight = true;
  config.use_weight_dropoff = false;
  map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegrator integrator(config);
  const std::vector<Vec3f> point = {Vec3f(1.0f, 0.05f, 0.05f)};
  integrator.integrate(map, point, {Rgb8{100, 10, 0}}, Eigen::Isometry3d::Identity());
  integrator.integrate(map, point, {Rgb8{200, 30, 255}}, Eigen::Isometry3d::Identity());
  int coloured = 0;
  for (const map::HostBlock& block : map.snapshot()) {
    for (int x = 0; x < 8; ++x) {
      const double sdf = 1.0 - ((block.index.x * 8 + x) + 0.5) * 0.1;
      if (block.index.y != 0 || block.index.z != 0 || block.tsdf[x].weight == 0.0f) continue;
      const map::ColorVoxel& c = block.color[x];
      if (std::abs(sdf) < 0.3 - 1e-4) {
        EXPECT_EQ(c.r, 150);
        EXPECT_EQ(c.g, 20);
        EXPECT_EQ(c.b, 128);  // (0 + 255) / 2 = 127.5, rounded
        EXPECT_FLOAT_EQ(c.weight, 2.0f);
        ++coloured;
      } else {
        EXPECT_EQ(c.weight, 0.0f) << "free space must not take colour";
      }
    }
  }
  EXPECT_EQ(coloured, 6);  // sdf in {0.25, 0.15, 0.05, -0.05, -0.15, -0.25}
}

TEST_P(TsdfIntegratorTest, IntensityIsFusedAsGreyWhenThereIsNoColour) {
  integrators::TsdfIntegratorConfig config;
  config.truncation_distance_m = 0.3f;
  map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegrator integrator(config);
  const Stream stream(device());
  auto points = Buffer<Vec3f>::from_host(device(), {Vec3f(1.0f, 0.05f, 0.05f)});
  auto intensities = Buffer<float>::from_host(device(), {50.0f});
  integrators::PointCloudView cloud{points.data(), nullptr, 1, intensities.data(), 100.0f};
  integrator.integrate(map, cloud, Eigen::Isometry3d::Identity(), stream);
  int grey = 0;
  for (const map::HostBlock& block : map.snapshot()) {
    for (const map::ColorVoxel& c : block.color) {
      if (c.weight == 0.0f) continue;
      EXPECT_EQ(c.r, 127);
      EXPECT_EQ(c.g, 127);
      EXPECT_EQ(c.b, 127);
      ++grey;
    }
  }
  EXPECT_EQ(grey, 6);
}

TEST_P(TsdfIntegratorTest, SameInputTwiceGivesBitIdenticalMaps) {
  const AnalyticScene scene = make_scene(Shape::kBox);
  std::vector<std::vector<map::HostBlock>> snapshots;
  for (int run = 0; run < 2; ++run) {
    map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 16, {}});
    integrators::TsdfIntegrator integrator(analytic_config(0.1f));
    for (const auto& pose : viewpoints()) {
      integrator.integrate(map, testing_support::simulate_lidar(scene, pose, 512, 32, 60.0, 9.5),
                           {}, pose);
    }
    snapshots.push_back(map.snapshot());
  }
  expect_bit_identical_tsdf(snapshots[0], snapshots[1]);
}

// A depth image is unprojected on the device into points in tile order (tsdf_unproject_depth).
// The map must be the one built from the same points unprojected on the host (pixel by pixel,
// placed in tile order) and integrated as a coloured point cloud: bit for bit, with the same
// counts, with either method. Sizes that are not multiples of the tile, invalid pixels, raw units
// and metres.
TEST_P(TsdfIntegratorTest, DepthImagesMatchHostUnprojectedPoints) {
  const AnalyticScene scene = make_scene(Shape::kBox);
  const int width = 157, height = 117;
  const float fx = 140.0f, fy = 138.0f, cx = 77.5f, cy = 60.25f;
  Eigen::Isometry3d camera = viewpoints()[1];
  camera.linear() =
      camera.linear() * Eigen::Matrix3d(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
  std::vector<uint16_t> depth =
      testing_support::simulate_depth_mm(scene, camera, width, height, fx, fy, cx, cy, 80.0);
  for (size_t p = 0; p < depth.size(); p += 7) depth[p] = p % 2 ? 0 : 65535;  // no measurement
  std::vector<float> depth_metres(depth.size());
  for (size_t p = 0; p < depth.size(); ++p)
    depth_metres[p] = depth[p] == 65535 ? NAN : depth[p] * 1e-3f;
  std::vector<Rgb8> colours(depth.size());
  for (size_t p = 0; p < colours.size(); ++p)
    colours[p] = Rgb8{uint8_t(p), uint8_t(p / 3), uint8_t(p * 5)};
  for (const integrators::TsdfIntegrationMethod method :
       {integrators::TsdfIntegrationMethod::kMerged, integrators::TsdfIntegrationMethod::kSimple}) {
    for (const bool metres : {false, true}) {
      SCOPED_TRACE(
          std::string(method == integrators::TsdfIntegrationMethod::kMerged ? "merged" : "simple") +
          (metres ? ", metres" : ", raw units"));
      // The host's points: ((u - cx) z / fx, (v - cy) z / fy, z), the zero point for no
      // measurement.
      std::vector<Vec3f> points(depth.size());
      std::vector<Rgb8> point_colours(depth.size());
      for (int v = 0; v < height; ++v) {
        for (int u = 0; u < width; ++u) {
          const size_t p = static_cast<size_t>(v) * width + u;
          const float z =
              metres ? (std::isfinite(depth_metres[p]) && depth_metres[p] > 0.0f ? depth_metres[p]
                                                                                 : 0.0f)
                     : (depth[p] == 0 || depth[p] == 65535 ? 0.0f : depth[p] * (1.0f / 1000.0f));
          const size_t place =
              static_cast<size_t>(integrators::tsdf::pixel_tile_order(u, v, width, height));
          points[place] = z == 0.0f
                              ? Vec3f(0.0f, 0.0f, 0.0f)
                              : Vec3f((u - cx) * z * (1.0f / fx), (v - cy) * z * (1.0f / fy), z);
          point_colours[place] = colours[p];
        }
      }
      integrators::TsdfIntegratorConfig config = analytic_config(0.05f);
      config.method = method;
      integrators::TsdfIntegrator in_place(config), from_points(config);
      map::TsdfMap a(device(), map::TsdfMapConfig{0.05f, 8, {}}),
          b(device(), map::TsdfMapConfig{0.05f, 8, {}});
      const auto depth_device = Buffer<uint16_t>::from_host(device(), depth);
      const auto metres_device = Buffer<float>::from_host(device(), depth_metres);
      const auto colours_device = Buffer<Rgb8>::from_host(device(), colours);
      integrators::DepthImageView image;
      if (metres) {
        image.depth_m = metres_device.data();
      } else {
        image.depth = depth_device.data();
      }
      image.colors = colours_device.data();
      image.intrinsics = integrators::PinholeIntrinsics{fx, fy, cx, cy, width, height};
      image.depth_units_per_m = 1000.0f;
      image.invalid_value = 65535;
      const Stream stream(device());
      const integrators::IntegrationStats read = in_place.integrate_depth(a, image, camera, stream);
      const integrators::IntegrationStats unprojected =
          from_points.integrate(b, points, point_colours, camera);
      EXPECT_EQ(read.points_in, unprojected.points_in);
      EXPECT_EQ(read.dropped_zero, unprojected.dropped_zero);
      EXPECT_GT(read.dropped_zero, static_cast<int64_t>(depth.size() / 8));
      EXPECT_EQ(read.rays_cast, unprojected.rays_cast);
      EXPECT_EQ(read.voxel_updates, unprojected.voxel_updates);
      EXPECT_EQ(read.voxels_updated, unprojected.voxels_updated);
      const std::vector<map::HostBlock> map_a = a.snapshot(), map_b = b.snapshot();
      ASSERT_GT(map_a.size(), 10u);
      expect_bit_identical_tsdf(map_a, map_b);
      for (size_t k = 0; k < map_a.size() && k < map_b.size(); ++k) {
        for (size_t v = 0; v < map_a[k].color.size(); ++v) {
          const map::ColorVoxel& x = map_a[k].color[v];
          const map::ColorVoxel& y = map_b[k].color[v];
          ASSERT_TRUE(x.r == y.r && x.g == y.g && x.b == y.b && x.weight == y.weight)
              << "colour of voxel " << v << " of block " << k;
        }
      }
    }
  }
}

// An erased block's slot goes back to the table's free stack, and a later frame that activates a
// block may get it, stale voxels and all: the frame must find such a block as empty as a block
// that never existed, whichever way it writes its voxels (the GPU's default path and every visit
// summed on the CPU clear the new blocks in their pass over the summed cells, the CPU's default
// path in a kernel of its own). Reference: a fresh map that integrates only the last frame.
TEST_P(TsdfIntegratorTest, ErasedBlocksComeBackEmpty) {
  const AnalyticScene scene = make_scene(Shape::kBox);
  const auto poses = viewpoints();
  for (const bool every_visit_summed : {false, true}) {
    SCOPED_TRACE(every_visit_summed ? "every visit summed" : "default path");
    integrators::TsdfIntegrator integrator(analytic_config(0.1f));
    if (every_visit_summed)
      integrators::tsdf::IntegratorInternals::set_strategy(integrator, summing_strategy());
    map::TsdfMap reused(device(), map::TsdfMapConfig{0.1f, 8, {}});
    map::TsdfMap fresh(device(), map::TsdfMapConfig{0.1f, 8, {}});
    const std::vector<Vec3f> last =
        testing_support::simulate_lidar(scene, poses[0], 512, 32, 60.0, 9.5);
    const std::vector<Rgb8> last_colours(last.size(), Rgb8{20, 140, 230});
    for (const auto& pose : poses) {
      const std::vector<Vec3f> points =
          testing_support::simulate_lidar(scene, pose, 512, 32, 60.0, 9.5);
      integrator.integrate(reused, points, std::vector<Rgb8>(points.size(), Rgb8{250, 5, 5}), pose);
    }
    std::vector<Index3D> keys;
    for (const map::HostBlock& block : reused.snapshot()) keys.push_back(block.index);
    ASSERT_GT(keys.size(), 10u);
    const Buffer<Index3D> device_keys = Buffer<Index3D>::from_host(device(), keys);
    ASSERT_EQ(reused.blocks().erase(device_keys.data(), static_cast<int64_t>(keys.size())),
              static_cast<int64_t>(keys.size()));
    ASSERT_EQ(reused.block_count(), 0);
    const integrators::IntegrationStats again =
        integrator.integrate(reused, last, last_colours, poses[0]);
    const integrators::IntegrationStats once =
        integrator.integrate(fresh, last, last_colours, poses[0]);
    EXPECT_EQ(again.blocks_allocated, once.blocks_allocated);
    EXPECT_EQ(again.voxels_updated, once.voxels_updated);
    const std::vector<map::HostBlock> a = reused.snapshot(), b = fresh.snapshot();
    expect_bit_identical_tsdf(a, b);
    for (size_t k = 0; k < a.size() && k < b.size(); ++k) {
      for (size_t v = 0; v < a[k].color.size(); ++v) {  // (field by field: the struct has padding)
        const map::ColorVoxel& x = a[k].color[v];
        const map::ColorVoxel& y = b[k].color[v];
        ASSERT_TRUE(x.r == y.r && x.g == y.g && x.b == y.b && x.weight == y.weight)
            << "colour of voxel " << v << " of block " << k << ": " << int(x.r) << " " << int(x.g)
            << " " << int(x.b) << " weight " << x.weight << " against " << int(y.r) << " "
            << int(y.g) << " " << int(y.b) << " weight " << y.weight;
      }
    }
  }
}

// The merged method's bundle table lives with the integrator and is cleaned by each frame as it
// uses it, not cleared before the next. A frame must therefore come out the same whether the
// integrator merged other frames before it (here into another map) or not: bit-identical maps.
TEST_P(TsdfIntegratorTest, MergeTableLeavesNoTraceBetweenFrames) {
  const AnalyticScene scene = make_scene(Shape::kBox);
  const auto poses = viewpoints();
  std::vector<Vec3f> earlier =
      testing_support::simulate_lidar(scene, poses[1], 1024, 32, 60.0, 9.5);
  std::vector<Rgb8> earlier_colours(earlier.size(), Rgb8{200, 10, 30});
  const std::vector<Vec3f> frame =
      testing_support::simulate_lidar(scene, poses[0], 512, 32, 60.0, 9.5);
  integrators::TsdfIntegratorConfig config = analytic_config(0.1f);
  ASSERT_EQ(config.method, integrators::TsdfIntegrationMethod::kMerged);
  integrators::TsdfIntegrator used(config);
  map::TsdfMap other(device(), map::TsdfMapConfig{0.1f, 16, {}});
  // A larger cloud with colour from elsewhere (the table grows), then the frame itself (the same
  // keys hashed the same way: a slot left behind would double its bundle).
  used.integrate(other, earlier, earlier_colours, poses[1]);
  used.integrate(other, frame, std::vector<Rgb8>(frame.size(), Rgb8{9, 99, 199}), poses[0]);
  map::TsdfMap after_others(device(), map::TsdfMapConfig{0.1f, 16, {}});
  const integrators::IntegrationStats stats = used.integrate(after_others, frame, {}, poses[0]);
  map::TsdfMap fresh(device(), map::TsdfMapConfig{0.1f, 16, {}});
  const integrators::IntegrationStats fresh_stats =
      integrators::TsdfIntegrator(config).integrate(fresh, frame, {}, poses[0]);
  EXPECT_EQ(stats.rays_cast, fresh_stats.rays_cast);
  EXPECT_LT(stats.rays_cast, stats.surface_rays);  // bundles did form
  expect_bit_identical_tsdf(after_others.snapshot(), fresh.snapshot());
}

// Colour rides along: the same cloud with colours, or with colour fusion off (which moves the
// slimmer distance-only updates), gives the same distances and weights: bit-identical on the CPU
// (each voxel's updates summed left to right), equal up to float summation order on the GPU (CUB
// tiles a reduction by the value's size, so the two update types group the sums differently).
TEST_P(TsdfIntegratorTest, ColourDoesNotChangeDistancesOrWeights) {
  const AnalyticScene scene = make_scene(Shape::kBox);
  std::vector<std::vector<map::HostBlock>> snapshots;
  for (const bool with_colour : {true, false}) {
    integrators::TsdfIntegratorConfig config = analytic_config(0.1f);
    config.integrate_color = with_colour;
    map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 16, {}});
    integrators::TsdfIntegrator integrator(config);
    for (const auto& pose : viewpoints()) {
      const std::vector<Vec3f> points =
          testing_support::simulate_lidar(scene, pose, 512, 32, 60.0, 9.5);
      std::vector<Rgb8> colours(points.size());
      for (size_t i = 0; i < points.size(); ++i)
        colours[i] = Rgb8{uint8_t(i % 251), uint8_t(i % 13), 200};
      integrator.integrate(map, points, colours, pose);
    }
    snapshots.push_back(map.snapshot());
  }
  ASSERT_EQ(snapshots[0].size(), snapshots[1].size());
  ASSERT_FALSE(snapshots[0].empty());
  int coloured = 0;
  for (size_t b = 0; b < snapshots[0].size(); ++b) {
    ASSERT_EQ(snapshots[0][b].index, snapshots[1][b].index);
    if (device() == Device::kCpu) {
      ASSERT_EQ(0, std::memcmp(snapshots[0][b].tsdf.data(), snapshots[1][b].tsdf.data(),
                               snapshots[0][b].tsdf.size() * sizeof(map::TsdfVoxel)));
    }
    for (size_t v = 0; v < snapshots[0][b].tsdf.size(); ++v) {
      const map::TsdfVoxel& a = snapshots[0][b].tsdf[v];
      const map::TsdfVoxel& c = snapshots[1][b].tsdf[v];
      ASSERT_NEAR(a.distance_m, c.distance_m, 1e-5f);
      ASSERT_NEAR(a.weight, c.weight, 1e-5f * a.weight);
    }
    for (const map::ColorVoxel& c : snapshots[0][b].color) coloured += c.weight > 0.0f;
    for (const map::ColorVoxel& c : snapshots[1][b].color) EXPECT_EQ(c.weight, 0.0f);
  }
  EXPECT_GT(coloured, 100);  // the colour run did fuse colour
}

// Free-space visits summed in fixed point as the rays are walked, and every visit summed so (the
// band's distances and colours too), against every visit sorted and reduced: a depth camera and a
// LiDAR with colour, carving, several views. The same voxels and counts; distances and weights
// equal up to the fixed point's rounding and the order of float sums; colours within one level.
TEST_P(TsdfIntegratorTest, FixedPointSumsMatchEveryVisitSorted) {
  const AnalyticScene scene = make_scene(Shape::kBox);
  const int width = 160, height = 120;
  const double f = 140.0;
  std::vector<std::vector<map::HostBlock>> snapshots;
  std::vector<integrators::IntegrationStats> totals;
  // kSmallBudget: every visit asked for, but the scratch budget (36 MB) holds every visit's sums
  // (48 bytes per voxel of the box) only for the smaller boxes (0.68 and 0.72 M voxels) and the
  // free-space sums (8 bytes) for the others (0.8 to 2.3 M voxels): one integrator takes both
  // paths, in turn, with one scratch buffer.
  enum Sums { kEveryVisit, kFreeSpace, kSmallBudget, kNone };
  for (const Sums sums : {kEveryVisit, kFreeSpace, kSmallBudget, kNone}) {
    integrators::TsdfIntegratorConfig config = analytic_config(0.05f);
    config.max_ray_length_m = 8.0f;
    if (sums == kSmallBudget) config.fixed_point_sums_max_scratch_mb = 36;
    map::TsdfMap map(device(), map::TsdfMapConfig{0.05f, 8, {}});
    integrators::TsdfIntegrator integrator(config);
    // (these small frames too)
    integrators::tsdf::IntegratorInternals::set_strategy(
        integrator, summing_strategy(sums != kNone, sums != kFreeSpace));
    const Stream stream(device());
    integrators::IntegrationStats total;
    const auto add = [&](const integrators::IntegrationStats& s) {
      total.voxel_updates += s.voxel_updates;
      total.voxels_updated += s.voxels_updated;
      total.records_grouped += s.records_grouped;
      total.voxels_out_of_range += s.voxels_out_of_range;
      total.dropped_zero += s.dropped_zero;  // the merge's tally, cleared between frames
      total.dropped_non_finite += s.dropped_non_finite;
      total.dropped_too_far += s.dropped_too_far;
      total.surface_rays += s.surface_rays;
    };
    for (const auto& pose : viewpoints()) {
      Eigen::Isometry3d camera = pose;
      camera.linear() =
          pose.linear() * Eigen::Matrix3d(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
      const auto depth = testing_support::simulate_depth_mm(scene, camera, width, height, f, f,
                                                            width / 2.0, height / 2.0, 80.0);
      std::vector<Rgb8> colours(depth.size());
      for (size_t p = 0; p < colours.size(); ++p)
        colours[p] = Rgb8{uint8_t(p % 251), uint8_t(p % 13), 200};
      auto depth_device = Buffer<uint16_t>::from_host(device(), depth);
      auto colour_device = Buffer<Rgb8>::from_host(device(), colours);
      integrators::DepthImageView image;
      image.depth = depth_device.data();
      image.colors = colour_device.data();
      image.intrinsics = integrators::PinholeIntrinsics{float(f),      float(f), width / 2.0f,
                                                        height / 2.0f, width,    height};
      image.depth_units_per_m = 1000.0f;
      image.invalid_value = 65535;
      add(integrator.integrate_depth(map, image, camera, stream));
      std::vector<Vec3f> points = testing_support::simulate_lidar(scene, pose, 256, 32, 60.0, 7.5);
      // Bad returns, dropped and counted (the merge's tally, which each frame leaves clear).
      for (int k = 0; k < 5; ++k)
        points.push_back(Vec3f(std::numeric_limits<float>::quiet_NaN(), 0.0f, 0.0f));
      for (int k = 0; k < 3; ++k) points.push_back(Vec3f(0.0f, 0.0f, 0.0f));
      std::vector<Rgb8> lidar_colours(points.size());
      for (size_t i = 0; i < points.size(); ++i)
        lidar_colours[i] = Rgb8{uint8_t(i % 7), uint8_t(i % 253), 9};
      add(integrator.integrate(map, points, lidar_colours, pose));
    }
    snapshots.push_back(map.snapshot());
    totals.push_back(total);
  }
  // The free-space sums sorted only the band's records, the reference every visit, and with
  // every visit summed none was.
  const integrators::IntegrationStats& reference = totals[kNone];
  EXPECT_EQ(reference.records_grouped, reference.voxel_updates);
  EXPECT_EQ(reference.dropped_total(), 8 * static_cast<int64_t>(viewpoints().size()));
  EXPECT_LT(totals[kFreeSpace].records_grouped, totals[kFreeSpace].voxel_updates / 2);
  EXPECT_GT(totals[kFreeSpace].records_grouped, 0);
  EXPECT_EQ(totals[kEveryVisit].records_grouped, 0);
  EXPECT_GT(totals[kSmallBudget].records_grouped, 0);
  EXPECT_LT(totals[kSmallBudget].records_grouped, totals[kFreeSpace].records_grouped);
  for (const Sums sums : {kEveryVisit, kFreeSpace, kSmallBudget}) {
    SCOPED_TRACE(sums == kEveryVisit  ? "every visit summed"
                 : sums == kFreeSpace ? "free space summed"
                                      : "small budget");
    EXPECT_EQ(totals[sums].voxel_updates, reference.voxel_updates);
    EXPECT_EQ(totals[sums].voxels_updated, reference.voxels_updated);
    EXPECT_EQ(totals[sums].voxels_out_of_range, reference.voxels_out_of_range);
    EXPECT_EQ(totals[sums].dropped_total(), reference.dropped_total());
    EXPECT_EQ(totals[sums].surface_rays, reference.surface_rays);
    const std::vector<map::HostBlock>& summed = snapshots[sums];
    const std::vector<map::HostBlock>& sorted = snapshots[kNone];
    ASSERT_EQ(summed.size(), sorted.size());
    ASSERT_GT(summed.size(), 50u);
    int observed = 0, coloured = 0;
    for (size_t b = 0; b < summed.size(); ++b) {
      ASSERT_EQ(summed[b].index, sorted[b].index);
      for (size_t v = 0; v < summed[b].tsdf.size(); ++v) {
        const map::TsdfVoxel& a = summed[b].tsdf[v];
        const map::TsdfVoxel& c = sorted[b].tsdf[v];
        ASSERT_EQ(a.weight > 0.0f, c.weight > 0.0f);
        ASSERT_NEAR(a.distance_m, c.distance_m, 1e-5f);
        ASSERT_NEAR(a.weight, c.weight, 1e-5f * c.weight + 1e-6f);
        observed += a.weight > 0.0f;
        const map::ColorVoxel& ca = summed[b].color[v];
        const map::ColorVoxel& cc = sorted[b].color[v];
        ASSERT_NEAR(ca.weight, cc.weight, 1e-5f * cc.weight + 1e-6f);
        ASSERT_LE(std::abs(int(ca.r) - int(cc.r)), 1);
        ASSERT_LE(std::abs(int(ca.g) - int(cc.g)), 1);
        ASSERT_LE(std::abs(int(ca.b) - int(cc.b)), 1);
        coloured += ca.weight > 0.0f;
      }
    }
    EXPECT_GT(observed, 5000);
    EXPECT_GT(coloured, 500);
  }
}

TEST_P(TsdfIntegratorTest, BadPointsAreDroppedAndCounted) {
  integrators::TsdfIntegratorConfig config;
  config.max_ray_length_m = 5.0f;
  config.min_ray_length_m = 0.5f;
  config.allow_clear = false;
  map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegrator integrator(config);
  const float nan = std::numeric_limits<float>::quiet_NaN(),
              inf = std::numeric_limits<float>::infinity();
  const std::vector<Vec3f> points = {Vec3f(nan, 0, 0),  Vec3f(1, inf, 0), Vec3f(0, 0, 0),
                                     Vec3f(0.1f, 0, 0), Vec3f(50, 0, 0),  Vec3f(2, 0, 0)};
  const integrators::IntegrationStats stats =
      integrator.integrate(map, points, {}, Eigen::Isometry3d::Identity());
  EXPECT_EQ(stats.dropped_non_finite, 2);
  EXPECT_EQ(stats.dropped_zero, 1);
  EXPECT_EQ(stats.dropped_too_close, 1);
  EXPECT_EQ(stats.dropped_too_far, 1);
  EXPECT_EQ(stats.surface_rays, 1);
  EXPECT_GT(map.block_count(), 0);
  // With allow_clear the far point carves free space instead.
  config.allow_clear = true;
  integrators::TsdfIntegrator clearing(config);
  const integrators::IntegrationStats clear_stats =
      clearing.integrate(map, points, {}, Eigen::Isometry3d::Identity());
  EXPECT_EQ(clear_stats.clearing_rays, 1);
  EXPECT_EQ(clear_stats.dropped_too_far, 0);
  // A non-finite pose is refused, the map untouched.
  Eigen::Isometry3d bad = Eigen::Isometry3d::Identity();
  bad.translation().x() = nan;
  const int64_t blocks_before = map.block_count();
  EXPECT_THROW(integrator.integrate(map, points, {}, bad), Error);
  EXPECT_EQ(map.block_count(), blocks_before);
}

// The merged method keys its points without a tally of them first: dropped points travel as one
// bundle per reason and clearing rays stay alone, so its counts must equal the simple method's,
// point for point, on a cloud with every kind of point and many points per voxel.
TEST_P(TsdfIntegratorTest, MergedAndSimpleCountEveryPointAlike) {
  integrators::TsdfIntegratorConfig config;
  config.max_ray_length_m = 5.0f;
  config.min_ray_length_m = 0.5f;
  config.allow_clear = true;
  const float nan = std::numeric_limits<float>::quiet_NaN(),
              inf = std::numeric_limits<float>::infinity();
  std::vector<Vec3f> points;
  for (int i = 0; i < 400; ++i) {
    const float a = 0.01f * i;
    points.push_back(
        Vec3f(2.0f + 0.001f * (i % 7), 0.3f * std::sin(a), 0.3f * std::cos(a)));  // many per voxel
    if (i % 10 == 0) points.push_back(Vec3f(nan, 1.0f, 0.0f));
    if (i % 11 == 0) points.push_back(Vec3f(inf, 0.0f, 0.0f));
    if (i % 12 == 0) points.push_back(Vec3f(0.0f, 0.0f, 0.0f));
    if (i % 13 == 0) points.push_back(Vec3f(0.1f, 0.05f * (i % 3), 0.0f));      // too close
    if (i % 14 == 0) points.push_back(Vec3f(20.0f, 0.5f * std::sin(a), 1.0f));  // clears
  }
  integrators::IntegrationStats by_method[2];
  for (int m = 0; m < 2; ++m) {
    config.method = m == 0 ? integrators::TsdfIntegrationMethod::kSimple
                           : integrators::TsdfIntegrationMethod::kMerged;
    map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 8, {}});
    by_method[m] = integrators::TsdfIntegrator(config).integrate(map, points, {},
                                                                 Eigen::Isometry3d::Identity());
  }
  const integrators::IntegrationStats& simple = by_method[0];
  const integrators::IntegrationStats& merged = by_method[1];
  EXPECT_EQ(simple.dropped_non_finite, 40 + 37);
  EXPECT_EQ(simple.dropped_zero, 34);
  EXPECT_EQ(simple.dropped_too_close, 31);
  EXPECT_EQ(simple.clearing_rays, 29);
  EXPECT_EQ(simple.surface_rays, 400);
  for (const integrators::IntegrationStats& stats : by_method) {
    EXPECT_EQ(stats.points_in, static_cast<int64_t>(points.size()));
    EXPECT_EQ(stats.surface_rays + stats.clearing_rays + stats.dropped_total(), stats.points_in);
  }
  EXPECT_EQ(merged.dropped_non_finite, simple.dropped_non_finite);
  EXPECT_EQ(merged.dropped_zero, simple.dropped_zero);
  EXPECT_EQ(merged.dropped_too_close, simple.dropped_too_close);
  EXPECT_EQ(merged.dropped_too_far, simple.dropped_too_far);
  EXPECT_EQ(merged.clearing_rays, simple.clearing_rays);
  EXPECT_EQ(merged.surface_rays, simple.surface_rays);
  EXPECT_EQ(simple.rays_cast, 400 + 29);
  EXPECT_LT(merged.rays_cast, 29 + 60);  // 400 surface points in a handful of voxels, 29 alone
}

// Merge keys come from a box around the sensor sized by max_ray_length_m. How large that box is
// (here 20 m or 1.8 km across at 2 cm voxels, keys of about 30 or more than 32 bits) must not
// change which points bundle: the same cloud integrated both ways gives bit-identical maps.
TEST_P(TsdfIntegratorTest, MergeBoxSizeDoesNotChangeTheMap) {
  const AnalyticScene scene = make_scene(Shape::kSphere);
  const Eigen::Isometry3d pose = viewpoints()[0];
  std::vector<Vec3f> points;  // every return twice, so that bundles form at 2 cm too
  for (const Vec3f& p : testing_support::simulate_lidar(scene, pose, 256, 16, 60.0, 9.5))
    points.insert(points.end(), {p, p});
  std::vector<std::vector<map::HostBlock>> snapshots;
  std::vector<integrators::IntegrationStats> stats;
  for (float max_ray_length_m : {10.0f, 900.0f}) {  // 0.02 m voxels: 900 m needs > 32-bit keys
    integrators::TsdfIntegratorConfig config = analytic_config(0.02f);
    config.max_ray_length_m = max_ray_length_m;
    config.allow_clear = false;
    map::TsdfMap map(device(), map::TsdfMapConfig{0.02f, 8, {}});
    stats.push_back(integrators::TsdfIntegrator(config).integrate(map, points, {}, pose));
    snapshots.push_back(map.snapshot());
  }
  EXPECT_EQ(stats[0].rays_cast, stats[1].rays_cast);
  EXPECT_LE(2 * stats[0].rays_cast, stats[0].surface_rays);  // the twins did merge
  expect_bit_identical_tsdf(snapshots[0], snapshots[1]);
}

// Update keys are 32-bit when the frame's box of voxels allows and 64-bit otherwise. Three rays
// 40 m long at 2 cm span a box of more than 2^32 voxels (64-bit keys); each ray alone fits in
// 32 bits. The rays share voxels only next to the sensor, so the frame and the three one-ray
// frames must give the same map: equal voxels, distances and weights up to the rounding of one
// weighted average against three.
TEST_P(TsdfIntegratorTest, LongKeysAndShortKeysBuildTheSameMap) {
  integrators::TsdfIntegratorConfig config;
  config.method = integrators::TsdfIntegrationMethod::kSimple;
  config.truncation_distance_m = 0.06f;
  config.max_ray_length_m = 50.0f;
  config.use_const_weight = true;
  const std::vector<Vec3f> rays = {Vec3f(40.0f, 0.3f, 0.2f), Vec3f(-0.2f, 40.0f, 0.1f),
                                   Vec3f(0.1f, -0.3f, -40.0f)};
  const Eigen::Isometry3d pose = viewpoints()[2];
  map::TsdfMap together(device(), map::TsdfMapConfig{0.02f, 8, {}});
  map::TsdfMap apart(device(), map::TsdfMapConfig{0.02f, 8, {}});
  const integrators::IntegrationStats stats =
      integrators::TsdfIntegrator(config).integrate(together, rays, {}, pose);
  int64_t updates_apart = 0;
  for (const Vec3f& ray : rays)
    updates_apart +=
        integrators::TsdfIntegrator(config).integrate(apart, {ray}, {}, pose).voxel_updates;
  EXPECT_EQ(stats.voxel_updates, updates_apart);
  EXPECT_GT(stats.voxel_updates, 3 * 1900);
  const auto voxels_together = observed_voxels(together);
  const auto voxels_apart = observed_voxels(apart);
  ASSERT_EQ(voxels_together.size(), voxels_apart.size());
  EXPECT_EQ(stats.voxels_updated, static_cast<int64_t>(voxels_together.size()));
  for (const auto& [key, voxel] : voxels_apart) {
    const auto found = voxels_together.find(key);
    ASSERT_NE(found, voxels_together.end());
    EXPECT_NEAR(found->second.distance_m, voxel.distance_m, 1e-5f);
    EXPECT_NEAR(found->second.weight, voxel.weight, 1e-5f * voxel.weight);
  }
}

TEST_P(TsdfIntegratorTest, RejectsInvalidParametersByName) {
  integrators::TsdfIntegratorConfig config;
  config.truncation_distance_m = -1.0f;
  map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegrator integrator(config);
  try {
    integrator.integrate(map, {Vec3f(1, 0, 0)}, {}, Eigen::Isometry3d::Identity());
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("truncation_distance_m"), std::string::npos);
  }
  config = integrators::TsdfIntegratorConfig{};
  config.fixed_point_sums_max_scratch_mb = -1;
  try {
    integrators::TsdfIntegrator(config).integrate(map, {Vec3f(1, 0, 0)}, {},
                                                  Eigen::Isometry3d::Identity());
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("fixed_point_sums_max_scratch_mb"), std::string::npos);
  }
  EXPECT_THROW(map::TsdfMap(device(), map::TsdfMapConfig{0.1f, 12, {}}), Error);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(TsdfIntegratorTest);

// Three times: with each backend's default path (the frames' boxes are small enough for the
// GPU to sum every visit in fixed point: against the CPU's dense grouping of every visit), with
// every visit summed on both, and with only the free-space visits summed on both (the band's
// records compacted by the GPU in its traverse, by the CPU after it).
enum class ParityPaths { kDefaults, kEveryVisitSummed, kFreeSpaceSummed };
class TsdfIntegratorParity : public ::testing::TestWithParam<ParityPaths> {};
INSTANTIATE_TEST_SUITE_P(FixedPointSums, TsdfIntegratorParity,
                         ::testing::Values(ParityPaths::kDefaults, ParityPaths::kEveryVisitSummed,
                                           ParityPaths::kFreeSpaceSummed));

TEST_P(TsdfIntegratorParity, CpuAndCudaBuildTheSameMap) {
  COVOX_SKIP_WITHOUT_GPU();
  const AnalyticScene scene = make_scene(Shape::kBox);
  std::vector<std::vector<map::HostBlock>> snapshots;
  std::vector<std::vector<integrators::IntegrationStats>> stats(2);
  for (Device device : {Device::kCpu, Device::kCuda}) {
    map::TsdfMap map(device, map::TsdfMapConfig{0.05f, 8, {}});
    integrators::TsdfIntegrator integrator(analytic_config(0.05f));
    if (GetParam() != ParityPaths::kDefaults) {  // the CPU's too
      integrators::tsdf::IntegratorInternals::set_strategy(
          integrator, summing_strategy(true, GetParam() != ParityPaths::kFreeSpaceSummed));
    }
    for (const auto& pose : viewpoints()) {
      std::vector<Vec3f> points = testing_support::simulate_lidar(scene, pose, 720, 64, 90.0, 9.5);
      std::vector<Rgb8> colors(points.size());
      for (size_t i = 0; i < colors.size(); ++i)
        colors[i] = Rgb8{uint8_t(i), uint8_t(i * 7), uint8_t(i * 13)};
      stats[device == Device::kCuda].push_back(integrator.integrate(map, points, colors, pose));
    }
    snapshots.push_back(map.snapshot());
  }
  // The counts, found by different code on each backend (the CPU groups by block, the GPU finds
  // the dropped records' runs in its sorted keys), agree exactly.
  ASSERT_EQ(stats[0].size(), stats[1].size());
  for (size_t f = 0; f < stats[0].size(); ++f) {
    const integrators::IntegrationStats& cpu = stats[0][f];
    const integrators::IntegrationStats& gpu = stats[1][f];
    EXPECT_EQ(cpu.surface_rays, gpu.surface_rays) << "frame " << f;
    EXPECT_EQ(cpu.clearing_rays, gpu.clearing_rays) << "frame " << f;
    EXPECT_EQ(cpu.dropped_total(), gpu.dropped_total()) << "frame " << f;
    EXPECT_EQ(cpu.rays_cast, gpu.rays_cast) << "frame " << f;
    EXPECT_EQ(cpu.voxel_updates, gpu.voxel_updates) << "frame " << f;
    EXPECT_EQ(cpu.voxels_updated, gpu.voxels_updated) << "frame " << f;
    EXPECT_EQ(cpu.voxels_out_of_range, gpu.voxels_out_of_range) << "frame " << f;
    EXPECT_EQ(cpu.blocks_allocated, gpu.blocks_allocated) << "frame " << f;
    EXPECT_LT(gpu.records_grouped, gpu.voxel_updates / 2) << "frame " << f;
    if (GetParam() != ParityPaths::kDefaults) {
      EXPECT_EQ(cpu.records_grouped, gpu.records_grouped) << "frame " << f;
    }
    if (GetParam() == ParityPaths::kFreeSpaceSummed) {
      EXPECT_GT(gpu.records_grouped, 0) << "frame " << f;
    }
  }
  ASSERT_EQ(snapshots[0].size(), snapshots[1].size());
  for (size_t b = 0; b < snapshots[0].size(); ++b) {
    ASSERT_EQ(snapshots[0][b].index, snapshots[1][b].index);
    for (size_t v = 0; v < snapshots[0][b].tsdf.size(); ++v) {
      const map::TsdfVoxel& cpu = snapshots[0][b].tsdf[v];
      const map::TsdfVoxel& gpu = snapshots[1][b].tsdf[v];
      ASSERT_NEAR(cpu.distance_m, gpu.distance_m, 1e-4f);
      // Weights are float sums of thousands of per-update weights; the CUDA segmented reduce
      // adds them in a different (fixed) order than the CPU's sequential one, so they agree to a
      // few float ulps per addition, not bit for bit.
      ASSERT_NEAR(cpu.weight, gpu.weight, 2e-4f * std::max(1.0f, cpu.weight));
      ASSERT_NEAR(snapshots[0][b].color[v].r, snapshots[1][b].color[v].r, 1);
    }
  }
}

}  // namespace
}  // namespace covox

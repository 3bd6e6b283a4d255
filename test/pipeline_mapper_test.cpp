// pipeline::Mapper on both backends, against analytic scenes: a hollow sphere scanned by a LiDAR
// from inside (ESDF distances and gradients, mesh vertices, the saved mesh) and a room seen by a
// depth camera (mesh vertices on the walls); its configuration read from the configuration
// files, and its refusals.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include "covoxslam/io/ply_reader.h"
#include "covoxslam/pipeline/mapper.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "support/analytic_scene.h"
#include "support/error_message.h"
#include "support/scratch_folder.h"
#include "support/test_devices.h"

namespace covox {
namespace pipeline {
namespace {

using testing_support::AnalyticScene;
using testing_support::error_message_of;

constexpr double kRadius_m = 4.0;
constexpr double kVoxel_m = 0.2;  // the arche preset's

AnalyticScene sphere() {
  AnalyticScene scene;
  scene.shape = testing_support::Shape::kSphere;
  scene.radius = kRadius_m;
  return scene;
}

AnalyticScene room() {
  AnalyticScene scene;
  scene.shape = testing_support::Shape::kBox;
  scene.half_extent = Eigen::Vector3d(2.0, 1.5, 1.2);
  return scene;
}

// The `arche` preset (0.2 m voxels, LiDAR weighting) on `device`.
MapperConfig arche_on(Device device) {
  MapperConfig config = load_mapper_config({"arche"});
  config.device = device;
  return config;
}

// Eight LiDAR scans of the sphere while the sensor moves 1.4 m along x and turns.
void scan_sphere(Mapper* mapper) {
  for (int k = 0; k < 8; ++k) {
    Scan scan;
    scan.stamp_s = 0.1 * k;
    scan.T_odom_sensor.linear() =
        Eigen::AngleAxisd(0.4 * k, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    scan.T_odom_sensor.translation() = Eigen::Vector3d(0.2 * k - 0.7, 0.0, 0.0);
    scan.points_sensor_m =
        testing_support::simulate_lidar(sphere(), scan.T_odom_sensor, 256, 24, 40.0, 10.0);
    const integrators::IntegrationStats stats = mapper->integrate(scan, scan.T_odom_sensor);
    ASSERT_EQ(stats.points_in, static_cast<int64_t>(scan.points_sensor_m.size()));
  }
}

// Points near the equator (inside the LiDAR's +-20 degree fan) at `radius_m`, every 5 degrees.
std::vector<Vec3f> ring(double radius_m) {
  std::vector<Vec3f> points;
  for (int a = 0; a < 72; ++a) {
    const double angle = a * 5.0 * M_PI / 180.0;
    points.emplace_back(static_cast<float>(radius_m * std::cos(angle)),
                        static_cast<float>(radius_m * std::sin(angle)), 0.1f);
  }
  return points;
}

// How many of the mesh's vertices lie within `tolerance_m` of the scene's surface.
size_t vertices_on_surface(const map::Mesh& mesh, const AnalyticScene& scene, double tolerance_m) {
  size_t on = 0;
  for (const Vec3f& v : mesh.vertices_m) {
    if (std::abs(scene.signed_distance(Eigen::Vector3d(v.x, v.y, v.z))) <= tolerance_m) ++on;
  }
  return on;
}

class MapperTest : public testing_support::DeviceTest {};

TEST_P(MapperTest, EsdfOfAScannedSphereMatchesItsExactDistance) {
  Mapper mapper(arche_on(device()));
  scan_sphere(&mapper);
  const integrators::EsdfUpdateStats stats = mapper.update_esdf();
  EXPECT_GT(stats.changed_blocks, 0);
  int compared = 0, within_voxel = 0, gradients_right = 0;
  for (double radius_m : {3.0, 3.3, 3.6}) {
    const std::vector<Vec3f> points = ring(radius_m);
    const std::vector<integrators::EsdfSample> samples = mapper.query_esdf(points);
    ASSERT_EQ(samples.size(), points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      ++compared;
      if (!samples[i].valid) continue;
      const Eigen::Vector3d p(points[i].x, points[i].y, points[i].z);
      if (std::abs(samples[i].distance_m - sphere().signed_distance(p)) <= kVoxel_m) ++within_voxel;
      // The distance grows away from the wall: towards the centre.
      const Eigen::Vector3d gradient(samples[i].gradient.x, samples[i].gradient.y,
                                     samples[i].gradient.z);
      if (gradient.norm() > 0.1 && gradient.normalized().dot(-p.normalized()) > 0.8)
        ++gradients_right;
    }
  }
  EXPECT_GE(within_voxel, 0.95 * compared) << within_voxel << " of " << compared;
  EXPECT_GE(gradients_right, 0.9 * compared) << gradients_right << " of " << compared;
  // Outside the sphere and its band nothing was observed.
  for (const integrators::EsdfSample& sample : mapper.query_esdf(ring(kRadius_m + 2.0)))
    EXPECT_EQ(sample.valid, 0);
}

TEST_P(MapperTest, MeshOfAScannedSphereLiesOnItAndIsSavedAsIs) {
  Mapper mapper(arche_on(device()));
  scan_sphere(&mapper);
  const integrators::MeshUpdateStats update = mapper.update_mesh();
  EXPECT_GT(update.triangles, 1000);
  const map::Mesh mesh = mapper.extract_mesh();
  ASSERT_GT(mesh.triangle_count(), 1000u);
  EXPECT_GE(vertices_on_surface(mesh, sphere(), 0.5 * kVoxel_m), 0.98 * mesh.vertices_m.size());

  ScratchFolder folder;
  mapper.save_mesh(folder.file("sphere.ply"));
  const map::Mesh saved = io::read_mesh_ply(folder.file("sphere.ply"));
  EXPECT_EQ(saved.triangle_count(), mesh.triangle_count());
  EXPECT_EQ(saved.vertices_m.size(), mesh.vertices_m.size());
}

// One 0.1 s sweep of a LiDAR in the sphere while it flies 0.5 m along y and turns 30 degrees:
// column c fires at c / 256 of the sweep from the pose interpolated between the sweep's ends,
// each point in the sensor frame at its firing time, with that time.
Scan distorted_sweep() {
  Scan scan;
  scan.sweep.known = true;
  scan.sweep.end_s = 0.1;
  scan.sweep.T_odom_sensor_end.linear() =
      Eigen::AngleAxisd(M_PI / 6.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  scan.sweep.T_odom_sensor_end.translation() = Eigen::Vector3d(0.0, 0.5, 0.0);
  for (int c = 0; c < 256; ++c) {
    const double fraction = c / 256.0;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::AngleAxisd(fraction * M_PI / 6.0, Eigen::Vector3d::UnitZ()).matrix();
    pose.translation() = Eigen::Vector3d(0.0, 0.5 * fraction, 0.0);
    for (int r = 0; r < 24; ++r) {
      const double azimuth = 2.0 * M_PI * fraction,
                   elevation = (r / 23.0 - 0.5) * 40.0 * M_PI / 180;
      const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth),
                                      std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
      const double range_m = sphere().intersect(pose.translation(), pose.linear() * direction);
      const Eigen::Vector3f point = (direction * range_m).cast<float>();
      scan.points_sensor_m.emplace_back(point.x(), point.y(), point.z());
      scan.point_times_s.push_back(static_cast<float>(0.1 * fraction));
    }
  }
  return scan;
}

// The share of the mesh's vertices within half a voxel of the sphere after one distorted sweep.
double sweep_mesh_on_sphere(Device device, bool deskew) {
  MapperConfig config = arche_on(device);
  config.deskew.enabled = deskew;
  Mapper mapper(config);
  const Scan scan = distorted_sweep();
  const integrators::IntegrationStats stats = mapper.integrate(scan, scan.T_odom_sensor);
  EXPECT_EQ(stats.points_deskewed, deskew ? stats.points_in : 0);
  const map::Mesh mesh = mapper.extract_mesh();
  EXPECT_GT(mesh.triangle_count(), 500u);
  return static_cast<double>(vertices_on_surface(mesh, sphere(), 0.5 * kVoxel_m)) /
         std::max<size_t>(1, mesh.vertices_m.size());
}

TEST_P(MapperTest, PointTimesDeskewASweepOntoTheSurface) {
  const double deskewed = sweep_mesh_on_sphere(device(), true);
  const double as_measured = sweep_mesh_on_sphere(device(), false);
  EXPECT_GE(deskewed, 0.98);
  EXPECT_LT(as_measured, 0.9);
}

// A depth camera at the room's centre turning about z, as io::RgbdFolder delivers its frames.
TEST_P(MapperTest, MeshOfARoomSeenByADepthCameraLiesOnItsWalls) {
  MapperConfig config = load_mapper_config({"rgbd"});
  config.device = device();
  config.map.voxel_size_m = 0.05f;
  config.tsdf.truncation_distance_m = 0.15f;
  Mapper mapper(config);
  io::RgbdFrame frame;
  frame.intrinsics = io::CameraIntrinsics{80.0, 80.0, 40.0, 30.0, 80, 60};
  frame.depth.width = 80;
  frame.depth.height = 60;
  for (int k = 0; k < 8; ++k) {
    // The camera looks along its +z: turn +z onto the horizontal, then about the vertical.
    frame.T_world_camera.linear() = (Eigen::AngleAxisd(k * M_PI / 4.0, Eigen::Vector3d::UnitZ()) *
                                     Eigen::AngleAxisd(-M_PI / 2.0, Eigen::Vector3d::UnitX()))
                                        .toRotationMatrix();
    const std::vector<uint16_t> depth_mm = testing_support::simulate_depth_mm(
        room(), frame.T_world_camera, 80, 60, 80.0, 80.0, 40.0, 30.0);
    frame.depth.depth_m.assign(depth_mm.begin(), depth_mm.end());
    for (float& d : frame.depth.depth_m) d *= 0.001f;
    mapper.integrate_depth(frame);
  }
  const map::Mesh mesh = mapper.extract_mesh();
  ASSERT_GT(mesh.triangle_count(), 1000u);
  EXPECT_GE(vertices_on_surface(mesh, room(), 0.05), 0.98 * mesh.vertices_m.size());
  // The camera turned all the way round: every wall was seen at its pose.
  int on_wall[4] = {0, 0, 0, 0};
  for (const Vec3f& v : mesh.vertices_m) {
    on_wall[0] += std::abs(v.x - 2.0f) < 0.05f;
    on_wall[1] += std::abs(v.x + 2.0f) < 0.05f;
    on_wall[2] += std::abs(v.y - 1.5f) < 0.05f;
    on_wall[3] += std::abs(v.y + 1.5f) < 0.05f;
  }
  for (int wall = 0; wall < 4; ++wall) EXPECT_GT(on_wall[wall], 100) << "wall " << wall;
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(MapperTest);

TEST(MapperConfigFiles, APresetAndAFileOverItReadAsForTheSlamSystem) {
  const SlamConfig slam = load_preset("arche");
  const MapperConfig preset = load_mapper_config({"arche"});
  EXPECT_EQ(preset.tsdf.use_const_weight, slam.tsdf.use_const_weight);
  EXPECT_EQ(preset.tsdf.sparsity_compensation_factor, slam.tsdf.sparsity_compensation_factor);
  EXPECT_EQ(preset.tsdf.max_ray_length_m, slam.tsdf.max_ray_length_m);

  ScratchFolder folder;
  const std::string path = folder.file("map.yaml");
  std::ofstream(path) << "map:\n  voxel_size_m: 0.1\ntsdf:\n  truncation_distance_m: 0.3\n"
                         "esdf:\n  max_distance_m: 1.5\nros:\n  base_frame: imu\n";
  const MapperConfig over = load_mapper_config({"arche", path});
  EXPECT_FLOAT_EQ(over.map.voxel_size_m, 0.1f);
  EXPECT_FLOAT_EQ(over.tsdf.truncation_distance_m, 0.3f);
  EXPECT_FLOAT_EQ(over.esdf.esdf_max_distance_m, 1.5f);
  EXPECT_EQ(over.tsdf.sparsity_compensation_factor, slam.tsdf.sparsity_compensation_factor);
  // The file alone starts from the library defaults.
  EXPECT_EQ(load_mapper_config({path}).tsdf.use_const_weight, SlamConfig().tsdf.use_const_weight);
}

TEST(MapperConfigFiles, BadNamesAndValuesAreReportedByName) {
  EXPECT_NE(error_message_of([] {
              load_mapper_config({"no_such_preset"});
            }).find("unknown preset 'no_such_preset'"),
            std::string::npos);
  ScratchFolder folder;
  const std::string path = folder.file("bad.yaml");
  std::ofstream(path) << "map:\n  voxel_size_m: -0.1\n";
  EXPECT_NE(error_message_of([&] { load_mapper_config({path}); }).find("map.voxel_size_m"),
            std::string::npos);
}

TEST(MapperRefusals, NameTheBadValue) {
  MapperConfig config = load_mapper_config({"arche"});
  config.tsdf.truncation_distance_m = 0.05f;  // under a voxel
  EXPECT_NE(error_message_of([&] { Mapper mapper(config); }).find("truncation"), std::string::npos);
  config = load_mapper_config({"arche"});
  config.esdf.esdf_max_distance_m = 0.0f;
  EXPECT_NE(error_message_of([&] { Mapper mapper(config); }).find("esdf.max_distance_m"),
            std::string::npos);

  Mapper mapper(load_mapper_config({"arche"}));
  Scan scan;
  scan.stamp_s = 2.5;
  scan.points_sensor_m = {Vec3f(1.0f, 0.0f, 0.0f), Vec3f(0.0f, 1.0f, 0.0f)};
  scan.colors = {Rgb8{}};
  EXPECT_NE(error_message_of([&] {
              mapper.integrate(scan, Eigen::Isometry3d::Identity());
            }).find("colour count"),
            std::string::npos);
  scan.colors.clear();
  Eigen::Isometry3d not_rigid = Eigen::Isometry3d::Identity();
  not_rigid.linear() *= 2.0;
  EXPECT_NE(error_message_of([&] { mapper.integrate(scan, not_rigid); }).find("rigid"),
            std::string::npos);
  io::RgbdFrame frame;
  frame.intrinsics = io::CameraIntrinsics{80.0, 80.0, 40.0, 30.0, 80, 60};
  frame.depth.width = 40;
  frame.depth.height = 30;
  frame.depth.depth_m.assign(40 * 30, 1.0f);
  EXPECT_NE(error_message_of([&] { mapper.integrate_depth(frame); }).find("40 x 30"),
            std::string::npos);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

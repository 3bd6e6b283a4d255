#include "covoxslam/pipeline/mapper.h"

#include <cmath>

#include "covoxslam/core/error.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/pipeline/scan_deskew.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

namespace {

void require(bool condition, const std::string& message) {
  if (!condition) throw Error("mapper: " + message);
}

bool ends_with(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// What keeps `scan` from being integrated, or nullptr.
const char* scan_problem(const Scan& scan, const Eigen::Isometry3d& T_map_sensor) {
  if (!is_valid_rigid_pose(T_map_sensor)) return "its pose is not a finite rigid transform";
  if (!scan.colors.empty() && scan.colors.size() != scan.points_sensor_m.size())
    return "its colour count does not match its point count";
  return point_times_problem(scan);
}

// Throws unless the depth image, the colour image (when there is one) and the intrinsics have
// one size.
void check_image_sizes(const io::RgbdFrame& frame) {
  const io::CameraIntrinsics& k = frame.intrinsics;
  const size_t pixels = static_cast<size_t>(k.width) * static_cast<size_t>(k.height);
  require(frame.depth.width == k.width && frame.depth.height == k.height &&
              frame.depth.depth_m.size() == pixels,
          "the depth image (" + std::to_string(frame.depth.width) + " x " +
              std::to_string(frame.depth.height) + ") does not match its intrinsics (" +
              std::to_string(k.width) + " x " + std::to_string(k.height) + ")");
  require(frame.color.empty() || (frame.color.width == k.width && frame.color.height == k.height &&
                                  frame.color.rgb.size() == 3 * pixels),
          "the colour image (" + std::to_string(frame.color.width) + " x " +
              std::to_string(frame.color.height) + ") does not match the depth image (" +
              std::to_string(k.width) + " x " + std::to_string(k.height) + ")");
}

std::vector<Rgb8> rgb_pixels(const io::ColorImage& image) {
  std::vector<Rgb8> pixels(image.rgb.size() / 3);
  for (size_t p = 0; p < pixels.size(); ++p)
    pixels[p] = Rgb8{image.rgb[3 * p], image.rgb[3 * p + 1], image.rgb[3 * p + 2]};
  return pixels;
}

}  // namespace

MapperConfig mapper_config(const SlamConfig& config) {
  MapperConfig mapper;
  mapper.device = config.device;
  mapper.map = config.map;
  mapper.tsdf = config.tsdf;
  mapper.esdf = config.esdf;
  mapper.mesh = config.mesh;
  mapper.deskew = config.deskew;
  return mapper;
}

MapperConfig load_mapper_config(const std::vector<std::string>& presets_or_files) {
  SlamConfig config;
  for (const std::string& entry : presets_or_files) {
    load_slam_config(ends_with(entry, ".yaml") ? entry : preset_path(entry), &config);
  }
  return mapper_config(config);
}

void validate(const MapperConfig& config) {
  require(std::isfinite(config.map.voxel_size_m) && config.map.voxel_size_m > 0.0f,
          "map.voxel_size_m must be positive, got " + std::to_string(config.map.voxel_size_m));
  require(config.map.voxels_per_side == 8 || config.map.voxels_per_side == 16,
          "map.voxels_per_side must be 8 or 16, got " + std::to_string(config.map.voxels_per_side));
  integrators::validate(config.tsdf, config.map.voxel_size_m);
  require(std::isfinite(config.esdf.esdf_max_distance_m) && config.esdf.esdf_max_distance_m > 0.0f,
          "esdf.max_distance_m must be positive, got " +
              std::to_string(config.esdf.esdf_max_distance_m));
  require(std::isfinite(config.deskew.sweep_duration_s) && config.deskew.sweep_duration_s > 0.0,
          "deskew.sweep_duration_s must be positive, got " +
              std::to_string(config.deskew.sweep_duration_s));
  require(config.device != Device::kCuda || cuda_device_available(),
          "device cuda: no usable GPU (or the library was built without CUDA); use cpu or auto");
}

namespace {
// Validates before any member is built, so a bad configuration reports its parameter instead of
// whatever a member's constructor makes of it.
const MapperConfig& validated(const MapperConfig& config) {
  validate(config);
  return config;
}
}  // namespace

Mapper::Mapper(const MapperConfig& config)
    : config_(validated(config)),
      integrators_(config.tsdf, config.esdf, config.mesh, Stream(config.device)),
      map_(config.device, config.map),
      points_(config.device),
      colors_(config.device),
      times_s_(config.device),
      depth_m_(config.device) {}

integrators::IntegrationStats Mapper::integrate(const Scan& scan,
                                                const Eigen::Isometry3d& T_map_sensor) {
  if (const char* problem = scan_problem(scan, T_map_sensor)) {
    throw Error("mapper: cannot integrate the scan at " + std::to_string(scan.stamp_s) +
                " s because " + problem);
  }
  const DeskewPlan deskew = plan_deskew(config_.deskew, scan);
  const integrators::PointCloudView cloud =
      upload_scan(scan, deskew, &points_, &colors_, &times_s_, stream());
  return integrate(cloud, T_map_sensor);
}

integrators::IntegrationStats Mapper::integrate(const integrators::PointCloudView& cloud,
                                                const Eigen::Isometry3d& T_map_sensor) {
  return integrators_.integrate(map_, cloud, T_map_sensor);
}

integrators::IntegrationStats Mapper::integrate_depth(const io::RgbdFrame& frame) {
  check_image_sizes(frame);
  depth_m_.copy_from_host(frame.depth.depth_m, stream());
  colors_.copy_from_host(rgb_pixels(frame.color), stream());
  const io::CameraIntrinsics& k = frame.intrinsics;
  integrators::DepthImageView image;
  image.depth_m = depth_m_.data();
  image.colors = frame.color.empty() ? nullptr : colors_.data();
  image.intrinsics = {static_cast<float>(k.fx),
                      static_cast<float>(k.fy),
                      static_cast<float>(k.cx),
                      static_cast<float>(k.cy),
                      k.width,
                      k.height};
  return integrate_depth(image, frame.T_world_camera);
}

integrators::IntegrationStats Mapper::integrate_depth(const integrators::DepthImageView& image,
                                                      const Eigen::Isometry3d& T_map_camera) {
  require(is_valid_rigid_pose(T_map_camera), "the camera pose is not a finite rigid transform");
  return integrators_.integrate_depth(map_, image, T_map_camera);
}

integrators::EsdfUpdateStats Mapper::update_esdf() { return integrators_.update_esdf(map_); }

integrators::EsdfUpdateStats Mapper::update_esdf_all() {
  return integrators_.update_esdf_all(map_);
}

integrators::MeshUpdateStats Mapper::update_mesh() { return integrators_.update_mesh(map_); }

const std::map<Index3D, map::Mesh>& Mapper::block_meshes() { return integrators_.block_meshes(); }

map::Mesh Mapper::extract_mesh() { return integrators_.extract_mesh(map_); }

void Mapper::save_mesh(const std::string& path) { io::write_mesh_ply(path, extract_mesh()); }

std::vector<integrators::EsdfSample> Mapper::query_esdf(const std::vector<Vec3f>& points_m) const {
  return integrators::query_esdf(map_, points_m);
}

}  // namespace pipeline
}  // namespace covox

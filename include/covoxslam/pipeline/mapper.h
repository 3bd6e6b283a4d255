#pragma once
// Mapper: one map without the SLAM threads. It owns a TsdfMap (TSDF, colour and ESDF layers) on
// one device and the integration stage that keeps it (pipeline/map_integrators.h: the TSDF, ESDF
// and mesh integrators and the stream they run on), and works synchronously: a call returns when
// its work is done (examples/map_depth_folder.cpp); a SLAM submap is the same map, kept by a stage
// SlamSystem lends it. It is configured from the files the SLAM system reads (config/*.yaml), so a
// preset means the same map to run_slam, the nodelet and a Mapper; docs/design.md, "The data
// path", says more.
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/esdf_queries.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/io/sensor_data.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/map/tsdf_map.h"
#include "covoxslam/pipeline/map_integrators.h"
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

// The SlamConfig fields a map uses, under the same names (docs/parameters.md: device, map.*,
// tsdf.*, esdf.*, mesh.*, deskew.*).
struct MapperConfig {
  Device device = Device::kCpu;
  map::TsdfMapConfig map;
  integrators::TsdfIntegratorConfig tsdf;
  integrators::EsdfIntegratorConfig esdf;
  integrators::MeshIntegratorConfig mesh;
  DeskewConfig deskew;
};

// The map's part of a SLAM configuration.
MapperConfig mapper_config(const SlamConfig& config);

// The library defaults with each entry applied in order: a preset name (config/NAME.yaml, see
// preset_names()) or, for an entry ending in ".yaml", the path of a configuration file. Read by
// the code that reads them for SlamSystem (load_slam_config), so a file's `ros` section is
// ignored and an unknown key or bad value throws covox::Error naming the file, line and key.
MapperConfig load_mapper_config(const std::vector<std::string>& presets_or_files);

// Throws covox::Error naming the first invalid parameter (the checks SlamSystem makes).
void validate(const MapperConfig& config);

class Mapper {
 public:
  // Throws covox::Error for an invalid configuration (validate()).
  explicit Mapper(const MapperConfig& config);

  const MapperConfig& config() const { return config_; }
  Device device() const { return config_.device; }
  // The stream every call runs on (drained before each call returns).
  const Stream& stream() const { return integrators_.stream(); }
  map::TsdfMap& map() { return map_; }
  const map::TsdfMap& map() const { return map_; }

  // Integrates a scan (host memory) taken at T_map_sensor, e.g. scan.T_odom_sensor for a map in
  // the odometry frame. Points with times are de-skewed as SlamSystem de-skews them
  // (pipeline/scan_deskew.h) when config().deskew.enabled and the sweep's odometry is known.
  // Throws covox::Error naming the stamp and the problem for a pose that is not a finite rigid
  // transform, a colour count or point times that do not match the points.
  integrators::IntegrationStats integrate(const Scan& scan, const Eigen::Isometry3d& T_map_sensor);
  // A cloud already in device memory (of device()), taken at T_map_sensor.
  integrators::IntegrationStats integrate(const integrators::PointCloudView& cloud,
                                          const Eigen::Isometry3d& T_map_sensor);
  // An RGB-D frame as io::RgbdFolder reads it, at frame.T_world_camera (the colour when it has
  // one). Throws covox::Error when the depth image, the colour image and the intrinsics disagree
  // in size.
  integrators::IntegrationStats integrate_depth(const io::RgbdFrame& frame);
  // A depth image already in device memory, taken at T_map_camera.
  integrators::IntegrationStats integrate_depth(const integrators::DepthImageView& image,
                                                const Eigen::Isometry3d& T_map_camera);

  // The ESDF around the blocks whose TSDF changed since the last update.
  integrators::EsdfUpdateStats update_esdf();
  // The ESDF of the whole map.
  integrators::EsdfUpdateStats update_esdf_all();
  // Re-meshes the blocks whose TSDF changed since the last update (block_meshes()).
  integrators::MeshUpdateStats update_mesh();
  // The incrementally updated meshes, one per block.
  const std::map<Index3D, map::Mesh>& block_meshes();
  // The mesh of the whole map, vertices welded everywhere.
  map::Mesh extract_mesh();
  // Writes extract_mesh() as a PLY file; throws covox::Error naming the path when it cannot.
  void save_mesh(const std::string& path);

  // Trilinear ESDF distance and gradient at points in the map frame (after update_esdf()).
  std::vector<integrators::EsdfSample> query_esdf(const std::vector<Vec3f>& points_m) const;

 private:
  MapperConfig config_;
  MapIntegrators integrators_;
  map::TsdfMap map_;
  // Upload buffers of the host-memory inputs, kept between calls.
  Buffer<Vec3f> points_;
  Buffer<Rgb8> colors_;
  Buffer<float> times_s_;
  Buffer<float> depth_m_;
};

}  // namespace pipeline
}  // namespace covox

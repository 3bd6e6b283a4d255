#pragma once
// TsdfIntegrator: fuses point clouds (LiDAR, or depth images turned into points on the device)
// into a TsdfMap by raycasting, with the "merged" update of the coVoxSLAM paper (III-C/D). A frame
// runs the stages 0 de-skew, 1 rays, 2 walk, 3 group, 4 blocks and 5 write
// (internal/tsdf_integrator_impl.h), steered by one plan decided from the configuration, the
// backend and the frame's tally (internal/tsdf_frame_plan.h). No atomics touch voxel data and
// every float sum is taken in an order fixed by the input, so a frame gives one map whatever
// the threads do. docs/design.md ("TSDF integration") describes the stages and the CPU twin.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/sweep_motion.h"
#include "covoxslam/integrators/tsdf_integrator_config.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox::integrators {

namespace tsdf {
struct FrameStrategy;
class IntegratorInternals;
}  // namespace tsdf

// What one integration did; counters of dropped input are the "counted, logged drop".
struct IntegrationStats {
  int64_t points_in = 0;
  int64_t surface_rays = 0;
  int64_t clearing_rays = 0;
  int64_t dropped_non_finite = 0;
  int64_t dropped_zero = 0;
  int64_t dropped_too_close = 0;
  int64_t dropped_too_far = 0;
  int64_t rays_cast = 0;            // surface + clearing rays after merging points per voxel
  int64_t voxel_updates = 0;        // before merging
  int64_t voxels_updated = 0;       // distinct voxels written
  int64_t voxels_out_of_range = 0;  // voxels dropped: block outside the map's key range
  int64_t blocks_allocated = 0;     // new blocks this call
  int64_t points_deskewed = 0;      // moved to the cloud's pose by their times (stage 0)
  int64_t records_grouped = 0;      // visit records grouped by voxel (sorted) and reduced: every
                                    // visit, with free-space sums the band's (a bound on them),
                                    // with every visit summed none

  int64_t dropped_total() const {
    return dropped_non_finite + dropped_zero + dropped_too_close + dropped_too_far;
  }
};

// Points (and optional colours) in the sensor frame, in memory of the map's device.
// Without colours, an intensity channel (LiDAR) is fused as grey: intensity / intensity_max_value.
struct PointCloudView {
  const Vec3f* points = nullptr;
  const Rgb8* colors = nullptr;  // optional
  int64_t count = 0;
  const float* intensities = nullptr;  // optional, used when colors is null
  float intensity_max_value = 255.0f;  // intensity shown as white
  // Optional, one per point: seconds after the cloud's pose at which the point was measured. With
  // it every point is first de-skewed by `sweep` into the sensor frame at the cloud's pose.
  const float* times_s = nullptr;
  SweepMotion sweep;
};

// A pinhole camera; depth pixel (u, v) with depth z unprojects to ((u-cx) z/fx, (v-cy) z/fy, z).
struct PinholeIntrinsics {
  float fx = 0.0f, fy = 0.0f, cx = 0.0f, cy = 0.0f;
  int width = 0, height = 0;
};

// A depth image in memory of the map's device: either 16-bit raw values as sensors and datasets
// store them (`depth`, with depth_units_per_m and invalid_value), or metres (`depth_m`, 0 or
// non-finite = no measurement).
struct DepthImageView {
  const uint16_t* depth = nullptr;  // row-major, width x height
  const float* depth_m = nullptr;   // used instead of `depth` when set
  const Rgb8* colors = nullptr;     // optional, registered to the depth image
  PinholeIntrinsics intrinsics;
  float depth_units_per_m = 1000.0f;  // 1000 for millimetres (Kinect, 7-Scenes), 6553.5 Replica
  uint16_t invalid_value = 0;         // 0 is always invalid; this one too (e.g. 65535)
};

class TsdfIntegrator {
 public:
  explicit TsdfIntegrator(const TsdfIntegratorConfig& config);
  ~TsdfIntegrator();
  TsdfIntegrator(TsdfIntegrator&&) noexcept;
  TsdfIntegrator& operator=(TsdfIntegrator&&) noexcept;

  const TsdfIntegratorConfig& config() const { return config_; }

  // Integrates a cloud taken at pose T_map_sensor. Device memory of map.device().
  IntegrationStats integrate(map::TsdfMap& map, const PointCloudView& cloud,
                             const Eigen::Isometry3d& T_map_sensor, const Stream& stream);
  // Host-memory convenience: uploads, then integrates.
  IntegrationStats integrate(map::TsdfMap& map, const std::vector<Vec3f>& points,
                             const std::vector<Rgb8>& colors,
                             const Eigen::Isometry3d& T_map_sensor);
  // Unprojects a depth image on the device (its points and colours in tiles of 8 x 4 pixels:
  // tsdf::pixel_tile_order), then integrates the points.
  IntegrationStats integrate_depth(map::TsdfMap& map, const DepthImageView& image,
                                   const Eigen::Isometry3d& T_map_camera, const Stream& stream);

 private:
  friend class tsdf::IntegratorInternals;
  struct Scratch;
  TsdfIntegratorConfig config_;
  std::unique_ptr<Scratch> scratch_;
  // How frames merge their visits (internal/tsdf_frame_strategy.h); null: the shipped strategy.
  std::unique_ptr<tsdf::FrameStrategy> strategy_;
};

}  // namespace covox::integrators

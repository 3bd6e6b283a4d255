#pragma once
// The real-data inputs the benchmarks share (the COVOX_DATA_DIR folder, see its README), loaded
// once from disk and uploaded to a device, so that only integration, not file reading, is timed.
#include <Eigen/Geometry>

#include <string>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/tsdf_integrator.h"

namespace covox {
namespace tools {

// LiDAR scans in the sensor frame, on a device.
struct DeviceScans {
  std::vector<Buffer<Vec3f>> points;
  std::vector<Buffer<float>> times_s;  // empty, or one buffer per scan: each point's time
  size_t size() const { return points.size(); }
  // Scan i's points; with its times and `sweep` when the scans have times and `sweep` is given.
  integrators::PointCloudView view(size_t i, const integrators::SweepMotion* sweep = nullptr) const;
};

// RGB-D frames (depth in metres, colour, camera-to-world pose), on a device.
struct DeviceRgbdFrames {
  std::vector<Buffer<float>> depth_m;
  std::vector<Buffer<Rgb8>> color;  // empty buffers when loaded without colour
  std::vector<Eigen::Isometry3d> T_world_camera;
  integrators::PinholeIntrinsics intrinsics;
  size_t size() const { return depth_m.size(); }
  integrators::DepthImageView view(size_t i) const;
};

// Newer College Ouster OS1-64 deskewed scans (lidar-scans/newer_06, 3 scans).
DeviceScans load_ouster_scans(const std::string& data_directory, Device device);
// The same Newer College OS1-64 scans as the sensor gave them (raw, motion-distorted), with each
// point's time in the sweep (0 to 0.1 s).
DeviceScans load_ouster_timed_scans(const std::string& data_directory, Device device);
// KITTI Velodyne HDL-64 scans (lidar-scans/kitti_00, 2 scans).
DeviceScans load_kitti_scans(const std::string& data_directory, Device device);
// The first `count` frames of 7scenes-redkitchen (fewer if the folder has fewer).
DeviceRgbdFrames load_7scenes_frames(const std::string& data_directory, size_t count, Device device,
                                     bool with_color = true);

// With COVOX_PROFILE_STAGES=1: prints the stage breakdown gathered since the last call under the
// case's name (see core/stage_profiler.h) and starts a new one. Otherwise does nothing.
void print_stage_profile(const std::string& case_name);

// The median of `values` (the upper one of the middle two for an even count); 0 when empty.
double median_of(std::vector<double> values);

}  // namespace tools
}  // namespace covox

#pragma once
// Host-side sensor data as the dataset readers deliver it, before anything goes to a device.
// Plain structs: the readers fill them, the pipeline copies what it needs into device buffers.
#include <Eigen/Geometry>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace covox {
namespace io {

// A LiDAR (or depth-derived) point cloud in the sensor frame. `intensities`, `colors` and
// `times_s` are either empty (the source had none) or exactly as long as `points_m`.
struct PointCloud {
  std::vector<Eigen::Vector3f> points_m;
  std::vector<float> intensities;
  std::vector<std::array<uint8_t, 3>> colors;  // r, g, b
  std::vector<float> times_s;                  // seconds after the cloud's stamp (io/point_times.h)

  size_t size() const { return points_m.size(); }
  bool empty() const { return points_m.empty(); }
  bool has_intensities() const { return !intensities.empty(); }
  bool has_colors() const { return !colors.empty(); }
};

// Row-major depth in metres; 0 marks a pixel without a valid measurement (the convention of
// every RGB-D dataset we read, so no NaN ever reaches the integrator from here).
struct DepthImage {
  int width = 0;
  int height = 0;
  std::vector<float> depth_m;

  float at(int row, int column) const { return depth_m[static_cast<size_t>(row) * width + column]; }
};

// Row-major 8-bit colour, three bytes per pixel in r, g, b order.
struct ColorImage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;

  bool empty() const { return rgb.empty(); }
  std::array<uint8_t, 3> at(int row, int column) const {
    const size_t first = 3 * (static_cast<size_t>(row) * width + column);
    return {rgb[first], rgb[first + 1], rgb[first + 2]};
  }
};

// Pinhole intrinsics in pixels; width/height are the image size they belong to.
struct CameraIntrinsics {
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  int width = 0;
  int height = 0;
};

// One RGB-D frame with its reference pose. `color` is empty when the dataset has no colour image
// for the frame.
struct RgbdFrame {
  DepthImage depth;
  ColorImage color;
  CameraIntrinsics intrinsics;
  Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();
  double timestamp_s = 0.0;
};

// What a reader repaired or dropped instead of failing. Readers add to it (never reset it), so
// one ReadStats can total a whole sequence.
struct ReadStats {
  size_t dropped_non_finite_points = 0;  // NaN/Inf points removed from clouds
  size_t reorthonormalized_poses = 0;    // rotations projected back onto SO(3) beyond tolerance
  size_t invalid_depth_pixels = 0;       // depth pixels set to 0 (no return / saturated)
};

}  // namespace io
}  // namespace covox

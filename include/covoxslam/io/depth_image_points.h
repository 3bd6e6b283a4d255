#pragma once
// Turning a depth image (and an optional registered colour image) into points in the camera
// frame, without ROS types: the ROS layer copies sensor_msgs/Image and CameraInfo fields into
// these plain structs, and the checks of a foreign image (encoding, step, size, intrinsics) are
// decided here where the main test suite checks them.
//
// Depth encodings: "16UC1" / "mono16" (millimetres, 0 = no measurement) and "32FC1" (metres,
// 0 or non-finite = no measurement). Colour encodings: rgb8, bgr8, rgba8, bgra8, mono8. The
// colour image must have the depth image's size (registered, as RGB-D drivers publish it).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/core/vec3.h"
#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {

struct ImageLayout {
  uint32_t width = 0;
  uint32_t height = 0;
  uint32_t step = 0;  // bytes per row
  std::string encoding;
  bool is_bigendian = false;
};

struct DepthToPointsOptions {
  int pixel_stride = 1;        // use every n-th pixel in both directions (1: all)
  float max_depth_m = 100.0f;  // deeper pixels are treated as no measurement
};

struct DepthPoints {
  std::vector<Vec3f> points_m;  // camera frame: x right, y down, z forward
  std::vector<Rgb8> colors;     // empty, or one per point
  int64_t pixels_used = 0;      // pixels visited (after the stride)
  int64_t pixels_invalid = 0;   // of those, without a valid depth
};

// Empty when fine, else a message naming the problem. `color` may be null.
std::string check_depth_input(const ImageLayout& depth, size_t depth_bytes,
                              const CameraIntrinsics& intrinsics, const ImageLayout* color,
                              size_t color_bytes);

// Unprojects every valid pixel; throws nothing: returns the check_depth_input() message and leaves
// `points` empty when the input is not usable.
std::string depth_image_to_points(const ImageLayout& depth, const uint8_t* depth_data,
                                  size_t depth_bytes, const CameraIntrinsics& intrinsics,
                                  const ImageLayout* color, const uint8_t* color_data,
                                  size_t color_bytes, const DepthToPointsOptions& options,
                                  DepthPoints* points);

}  // namespace io
}  // namespace covox

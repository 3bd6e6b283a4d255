#include "covoxslam/io/depth_image_points.h"

#include <cmath>
#include <cstring>

namespace covox {
namespace io {

namespace {

// Bytes per pixel of a supported encoding, 0 for an unsupported one.
size_t depth_pixel_bytes(const std::string& encoding) {
  if (encoding == "16UC1" || encoding == "mono16") return 2;
  if (encoding == "32FC1") return 4;
  return 0;
}

size_t color_pixel_bytes(const std::string& encoding) {
  if (encoding == "rgb8" || encoding == "bgr8") return 3;
  if (encoding == "rgba8" || encoding == "bgra8") return 4;
  if (encoding == "mono8") return 1;
  return 0;
}

std::string check_image(const char* what, const ImageLayout& image, size_t bytes,
                        size_t pixel_bytes) {
  const std::string name(what);
  if (pixel_bytes == 0) return name + " image has unsupported encoding '" + image.encoding + "'";
  if (image.is_bigendian && pixel_bytes > 1 && name == "depth") {
    return "depth image is big-endian; only little-endian images are read";
  }
  if (image.width == 0 || image.height == 0) return name + " image is empty";
  if (static_cast<uint64_t>(image.step) < static_cast<uint64_t>(image.width) * pixel_bytes) {
    return name + " image step " + std::to_string(image.step) + " bytes is less than width " +
           std::to_string(image.width) + " x " + std::to_string(pixel_bytes) + " bytes";
  }
  if (bytes < static_cast<uint64_t>(image.step) * image.height) {
    return name + " image has " + std::to_string(bytes) + " bytes, its size needs " +
           std::to_string(static_cast<uint64_t>(image.step) * image.height);
  }
  return "";
}

}  // namespace

std::string check_depth_input(const ImageLayout& depth, size_t depth_bytes,
                              const CameraIntrinsics& intrinsics, const ImageLayout* color,
                              size_t color_bytes) {
  std::string problem = check_image("depth", depth, depth_bytes, depth_pixel_bytes(depth.encoding));
  if (!problem.empty()) return problem;
  if (!(std::isfinite(intrinsics.fx) && intrinsics.fx > 0.0 && std::isfinite(intrinsics.fy) &&
        intrinsics.fy > 0.0 && std::isfinite(intrinsics.cx) && std::isfinite(intrinsics.cy))) {
    return "camera intrinsics are not usable (fx and fy must be positive, cx and cy finite)";
  }
  if (color) {
    problem = check_image("colour", *color, color_bytes, color_pixel_bytes(color->encoding));
    if (!problem.empty()) return problem;
    if (color->width != depth.width || color->height != depth.height) {
      return "colour image is " + std::to_string(color->width) + "x" +
             std::to_string(color->height) + " but the depth image is " +
             std::to_string(depth.width) + "x" + std::to_string(depth.height) +
             " (a registered colour image is required)";
    }
  }
  return "";
}

std::string depth_image_to_points(const ImageLayout& depth, const uint8_t* depth_data,
                                  size_t depth_bytes, const CameraIntrinsics& intrinsics,
                                  const ImageLayout* color, const uint8_t* color_data,
                                  size_t color_bytes, const DepthToPointsOptions& options,
                                  DepthPoints* points) {
  *points = DepthPoints{};
  std::string problem = check_depth_input(depth, depth_bytes, intrinsics, color, color_bytes);
  if (problem.empty() && options.pixel_stride < 1) problem = "pixel_stride must be at least 1";
  if (!problem.empty()) return problem;

  const bool millimetres = depth_pixel_bytes(depth.encoding) == 2;
  const size_t color_bytes_per_pixel = color ? color_pixel_bytes(color->encoding) : 0;
  const bool bgr = color && (color->encoding == "bgr8" || color->encoding == "bgra8");
  const int stride = options.pixel_stride;
  for (uint32_t v = 0; v < depth.height; v += stride) {
    const uint8_t* depth_row = depth_data + static_cast<size_t>(v) * depth.step;
    for (uint32_t u = 0; u < depth.width; u += stride) {
      ++points->pixels_used;
      float z_m;
      if (millimetres) {
        uint16_t raw;
        std::memcpy(&raw, depth_row + 2 * static_cast<size_t>(u), 2);
        z_m = raw * 0.001f;
      } else {
        std::memcpy(&z_m, depth_row + 4 * static_cast<size_t>(u), 4);
      }
      if (!std::isfinite(z_m) || z_m <= 0.0f || z_m > options.max_depth_m) {
        ++points->pixels_invalid;
        continue;
      }
      const float x = static_cast<float>((u - intrinsics.cx) * z_m / intrinsics.fx);
      const float y = static_cast<float>((v - intrinsics.cy) * z_m / intrinsics.fy);
      points->points_m.emplace_back(x, y, z_m);
      if (color) {
        const uint8_t* pixel =
            color_data + static_cast<size_t>(v) * color->step + color_bytes_per_pixel * u;
        if (color_bytes_per_pixel == 1) {
          points->colors.push_back(Rgb8{pixel[0], pixel[0], pixel[0]});
        } else if (bgr) {
          points->colors.push_back(Rgb8{pixel[2], pixel[1], pixel[0]});
        } else {
          points->colors.push_back(Rgb8{pixel[0], pixel[1], pixel[2]});
        }
      }
    }
  }
  return "";
}

}  // namespace io
}  // namespace covox

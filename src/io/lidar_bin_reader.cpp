#include "covoxslam/io/lidar_bin_reader.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/io/file_bytes.h"

namespace covox {
namespace io {
namespace {

// The stride whose median step between consecutive points is this many times shorter wins.
// In scan order a KITTI scan's consecutive points lie centimetres apart at the right stride and
// metres apart at the wrong one, so the margin is wide.
constexpr double kClearStepRatio = 4.0;
// Enough consecutive pairs for a stable median, few enough to stay cheap on big scans.
constexpr size_t kMaxStepSamples = 20000;

double median_consecutive_step_m(const std::vector<float>& values, size_t stride) {
  const size_t point_count = values.size() / stride;
  const size_t pair_count = std::min(point_count > 0 ? point_count - 1 : 0, kMaxStepSamples);
  std::vector<double> steps;
  steps.reserve(pair_count);
  for (size_t i = 0; i < pair_count; ++i) {
    double squared = 0.0;
    for (size_t axis = 0; axis < 3; ++axis) {
      const double delta =
          double(values[(i + 1) * stride + axis]) - double(values[i * stride + axis]);
      squared += delta * delta;
    }
    if (std::isfinite(squared)) steps.push_back(std::sqrt(squared));
  }
  if (steps.empty()) return 0.0;
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  return steps[steps.size() / 2];
}

bool could_be_intensity_column(const std::vector<float>& values) {
  for (size_t i = 3; i < values.size(); i += 4) {
    if (!std::isfinite(values[i]) || values[i] < 0.0f) return false;
  }
  return true;
}

}  // namespace

std::vector<float> read_float32_file(const std::string& path) {
  const std::vector<uint8_t> bytes = read_file_bytes(path);
  if (bytes.size() % sizeof(float) != 0) {
    throw Error("'" + path + "' has " + std::to_string(bytes.size()) +
                " bytes, not a whole number of float32 values: truncated or not a float32 file");
  }
  std::vector<float> values(bytes.size() / sizeof(float));
  std::memcpy(values.data(), bytes.data(),
              bytes.size());  // the files and all our hosts are little-endian
  return values;
}

BinPointLayout detect_bin_point_layout(const std::vector<float>& values, const std::string& path) {
  const bool fits_xyz = values.size() % 3 == 0;
  const bool fits_xyzi = values.size() % 4 == 0;
  if (values.empty()) return BinPointLayout::kXyz;
  if (fits_xyz && !fits_xyzi) return BinPointLayout::kXyz;
  if (fits_xyzi && !fits_xyz) return BinPointLayout::kXyzIntensity;
  if (!fits_xyz && !fits_xyzi) {
    throw Error("'" + path + "' holds " + std::to_string(values.size()) +
                " floats, a multiple of neither 3 (x,y,z) nor 4 (x,y,z,intensity): truncated?");
  }
  if (!could_be_intensity_column(values)) return BinPointLayout::kXyz;
  const double step_xyz_m = median_consecutive_step_m(values, 3);
  const double step_xyzi_m = median_consecutive_step_m(values, 4);
  if (step_xyz_m * kClearStepRatio < step_xyzi_m) return BinPointLayout::kXyz;
  if (step_xyzi_m * kClearStepRatio < step_xyz_m) return BinPointLayout::kXyzIntensity;
  throw Error("'" + path +
              "': cannot tell whether points have 3 (x,y,z) or 4 (x,y,z,intensity) floats: the " +
              "file size fits both and the content does not decide; pass the layout explicitly");
}

PointCloud read_lidar_bin(const std::string& path, BinPointLayout layout, ReadStats* stats) {
  const std::vector<float> values = read_float32_file(path);
  if (layout == BinPointLayout::kAutoDetect) layout = detect_bin_point_layout(values, path);
  const size_t stride = static_cast<size_t>(layout);
  if (values.size() % stride != 0) {
    throw Error("'" + path + "' holds " + std::to_string(values.size()) +
                " floats, not a multiple of " + std::to_string(stride) +
                " floats per point: truncated or wrong layout");
  }
  const size_t point_count = values.size() / stride;
  const bool with_intensity = layout == BinPointLayout::kXyzIntensity;

  PointCloud cloud;
  cloud.points_m.reserve(point_count);
  if (with_intensity) cloud.intensities.reserve(point_count);
  size_t dropped = 0;
  for (size_t i = 0; i < point_count; ++i) {
    const float* point = &values[i * stride];
    const Eigen::Vector3f position(point[0], point[1], point[2]);
    // A point is dropped whole when its position or intensity is not finite, so the intensity
    // array stays aligned with the points.
    if (!position.allFinite() || (with_intensity && !std::isfinite(point[3]))) {
      ++dropped;
      continue;
    }
    cloud.points_m.push_back(position);
    if (with_intensity) cloud.intensities.push_back(point[3]);
  }
  if (dropped > 0) {
    log_warning("'", path, "': dropped ", dropped, " of ", point_count,
                " points with NaN/Inf values");
    if (stats != nullptr) stats->dropped_non_finite_points += dropped;
  }
  return cloud;
}

}  // namespace io
}  // namespace covox

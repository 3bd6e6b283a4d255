#pragma once
// Decoding the bytes of a sensor_msgs/PointCloud2 into points (and colours) without ROS types.
// The ROS layer copies the message's field table and sizes into a PointCloudLayout and hands the
// data bytes over; everything that can go wrong with a foreign cloud - no x/y/z, a point step
// too small for its fields, data shorter than width x height, big-endian data, NaN points - is
// decided here, where the main test suite (which has no ROS) checks it.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/core/vec3.h"
#include "covoxslam/io/point_field_types.h"
#include "covoxslam/io/point_times.h"

namespace covox {
namespace io {

struct PointFieldDescription {
  std::string name;
  uint32_t offset = 0;   // bytes from the start of a point
  uint8_t datatype = 0;  // PointFieldType code
  uint32_t count = 1;    // elements
};

struct PointCloudLayout {
  std::vector<PointFieldDescription> fields;
  uint32_t width = 0;
  uint32_t height = 0;
  uint32_t point_step = 0;  // bytes per point
  uint32_t row_step = 0;    // bytes per row
  bool is_bigendian = false;
};

struct CloudDecodeOptions {
  bool use_color = true;                 // read `rgb` / `rgba` when present
  bool use_intensity = true;             // read `intensity` when there is no colour
  float intensity_max_value = 255.0f;    // intensity shown as white
  bool read_point_times = true;          // per-point times (point_times.h) when the cloud has them
  double column_sweep_duration_s = 0.1;  // organised clouds without a time field
};

enum class CloudDecodeStatus {
  kOk,
  kMissingXyz,         // no x, y or z field
  kXyzNotFloat32,      // x, y or z is not a single FLOAT32
  kUnknownFieldType,   // a field's datatype code is not a PointField type
  kPointStepTooSmall,  // a field reaches past point_step
  kRowStepTooSmall,    // row_step < width * point_step
  kDataTooShort,       // fewer bytes than height * row_step
  kBigEndian,          // big-endian data (not produced by any supported sensor driver)
};
const char* to_string(CloudDecodeStatus status);

struct DecodedCloud {
  std::vector<Vec3f> points_m;
  std::vector<Rgb8> colors;          // empty, or one per point
  int64_t points_in = 0;             // width x height
  int64_t dropped_non_finite = 0;    // points with a NaN or infinite coordinate
  bool has_color = false;            // colours came from rgb / rgba
  bool has_intensity = false;        // colours came from intensity (grey)
  std::vector<float> point_times_s;  // empty, or one per point: seconds after the stamp
  PointTimeSource time_source = PointTimeSource::kNone;
};

struct CloudDecodeResult {
  CloudDecodeStatus status = CloudDecodeStatus::kOk;
  std::string message;  // says what is wrong and with which field, empty when ok
  bool ok() const { return status == CloudDecodeStatus::kOk; }
};

// Checks `layout` (and that `data_size` bytes cover it) without reading any point.
CloudDecodeResult check_point_cloud_layout(const PointCloudLayout& layout, size_t data_size);

// Accepted: x, y, z as FLOAT32 (required) at any offsets, in any order, with any point step;
// optional colour from a packed `rgb` / `rgba` field (4 bytes, PCL's 0x00RRGGBB, stored as FLOAT32,
// UINT32 or INT32) or, when there is no colour, an `intensity` field of any numeric type shown as
// grey (intensity / intensity_max_value); per-point times from a `t` or `time` field or an
// organised cloud's column order (point_times.h). Points with a non-finite coordinate are dropped
// and counted; organised clouds (height > 1) are read row by row honouring row_step.
//
// Decodes `data` (data_size bytes) into `cloud` (cleared first). On an error `cloud` is left
// empty and the result names the problem.
CloudDecodeResult decode_point_cloud(const PointCloudLayout& layout, const uint8_t* data,
                                     size_t data_size, const CloudDecodeOptions& options,
                                     DecodedCloud* cloud);

}  // namespace io
}  // namespace covox

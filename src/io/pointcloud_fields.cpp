#include "covoxslam/io/pointcloud_fields.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace covox {
namespace io {

namespace {

const PointFieldDescription* find_field(const PointCloudLayout& layout, const char* name) {
  for (const PointFieldDescription& field : layout.fields) {
    if (field.name == name) return &field;
  }
  return nullptr;
}

// The `rgb` or `rgba` field; null when neither is a packed colour of 4 bytes (anything else is
// not PCL's convention and is ignored).
const PointFieldDescription* packed_color_field(const PointCloudLayout& layout) {
  const PointFieldDescription* rgb = find_field(layout, "rgb");
  if (!rgb) rgb = find_field(layout, "rgba");
  if (rgb && point_field_type_size(rgb->datatype) * rgb->count != 4) return nullptr;
  return rgb;
}

// PCL's packed 0x00RRGGBB colour.
Rgb8 packed_color(const uint8_t* at) {
  uint32_t packed;
  std::memcpy(&packed, at, 4);
  return Rgb8{static_cast<uint8_t>((packed >> 16) & 0xff),
              static_cast<uint8_t>((packed >> 8) & 0xff), static_cast<uint8_t>(packed & 0xff)};
}

// An intensity as grey: its value times `grey_scale`, clamped to [0, 255] (non-finite: black).
Rgb8 grey_of(const uint8_t* at, uint8_t datatype, double grey_scale) {
  const double value = read_point_field_element(at, datatype) * grey_scale;
  const double clamped = std::isfinite(value) ? std::min(255.0, std::max(0.0, value)) : 0.0;
  const uint8_t grey = static_cast<uint8_t>(std::lround(clamped));
  return Rgb8{grey, grey, grey};
}

CloudDecodeResult failure(CloudDecodeStatus status, std::string message) {
  return CloudDecodeResult{status, std::move(message)};
}

}  // namespace

const char* to_string(CloudDecodeStatus status) {
  switch (status) {
    case CloudDecodeStatus::kOk:
      return "ok";
    case CloudDecodeStatus::kMissingXyz:
      return "missing x/y/z field";
    case CloudDecodeStatus::kXyzNotFloat32:
      return "x/y/z not FLOAT32";
    case CloudDecodeStatus::kUnknownFieldType:
      return "unknown field datatype";
    case CloudDecodeStatus::kPointStepTooSmall:
      return "point step too small for its fields";
    case CloudDecodeStatus::kRowStepTooSmall:
      return "row step too small for its points";
    case CloudDecodeStatus::kDataTooShort:
      return "data shorter than the cloud's size";
    case CloudDecodeStatus::kBigEndian:
      return "big-endian data";
  }
  return "unknown";
}

CloudDecodeResult check_point_cloud_layout(const PointCloudLayout& layout, size_t data_size) {
  if (layout.is_bigendian) {
    return failure(CloudDecodeStatus::kBigEndian,
                   "the cloud is big-endian; only little-endian clouds are read");
  }
  for (const char* axis : {"x", "y", "z"}) {
    const PointFieldDescription* field = find_field(layout, axis);
    if (!field) {
      return failure(
          CloudDecodeStatus::kMissingXyz,
          std::string("the cloud has no '") + axis + "' field (x, y and z FLOAT32 are required)");
    }
    if (field->datatype != kFloat32 || field->count != 1) {
      return failure(CloudDecodeStatus::kXyzNotFloat32,
                     std::string("field '") + axis + "' has datatype " +
                         std::to_string(field->datatype) + " and count " +
                         std::to_string(field->count) +
                         "; x, y and z must be one FLOAT32 (7) each");
    }
  }
  // Every field must lie inside one point: a driver that got its point step wrong would
  // otherwise make us read the next point's bytes (or past the buffer) as this point's.
  for (const PointFieldDescription& field : layout.fields) {
    const size_t element_size = point_field_type_size(field.datatype);
    if (element_size == 0) {
      return failure(
          CloudDecodeStatus::kUnknownFieldType,
          "field '" + field.name + "' has unknown datatype " + std::to_string(field.datatype));
    }
    const uint64_t end =
        static_cast<uint64_t>(field.offset) + element_size * static_cast<uint64_t>(field.count);
    if (end > layout.point_step) {
      return failure(CloudDecodeStatus::kPointStepTooSmall,
                     "field '" + field.name + "' ends at byte " + std::to_string(end) +
                         " but the point step is " + std::to_string(layout.point_step) + " bytes");
    }
  }
  const uint64_t row_bytes = static_cast<uint64_t>(layout.width) * layout.point_step;
  if (layout.height > 0 && layout.row_step < row_bytes) {
    return failure(CloudDecodeStatus::kRowStepTooSmall,
                   "row step " + std::to_string(layout.row_step) + " bytes < width " +
                       std::to_string(layout.width) + " x point step " +
                       std::to_string(layout.point_step));
  }
  // The last row needs only its points, not a full row_step (some drivers trim the padding).
  const uint64_t needed =
      layout.height == 0 || layout.width == 0
          ? 0
          : static_cast<uint64_t>(layout.height - 1) * layout.row_step + row_bytes;
  if (data_size < needed) {
    return failure(CloudDecodeStatus::kDataTooShort, "the cloud has " + std::to_string(data_size) +
                                                         " data bytes but its size needs " +
                                                         std::to_string(needed));
  }
  return CloudDecodeResult{};
}

CloudDecodeResult decode_point_cloud(const PointCloudLayout& layout, const uint8_t* data,
                                     size_t data_size, const CloudDecodeOptions& options,
                                     DecodedCloud* cloud) {
  *cloud = DecodedCloud{};
  CloudDecodeResult check = check_point_cloud_layout(layout, data_size);
  if (!check.ok()) return check;

  const uint32_t x_offset = find_field(layout, "x")->offset;
  const uint32_t y_offset = find_field(layout, "y")->offset;
  const uint32_t z_offset = find_field(layout, "z")->offset;
  const PointFieldDescription* rgb = options.use_color ? packed_color_field(layout) : nullptr;
  const PointFieldDescription* intensity =
      (!rgb && options.use_intensity) ? find_field(layout, "intensity") : nullptr;
  const double grey_scale =
      options.intensity_max_value > 0.0f ? 255.0 / options.intensity_max_value : 0.0;

  const PointTimeReader times =
      options.read_point_times ? make_point_time_reader(layout.fields, layout.width, layout.height,
                                                        options.column_sweep_duration_s)
                               : PointTimeReader();
  cloud->time_source = times.source();
  cloud->has_color = rgb != nullptr;
  cloud->has_intensity = intensity != nullptr;
  cloud->points_in = static_cast<int64_t>(layout.width) * layout.height;
  if (times.has_times()) cloud->point_times_s.reserve(static_cast<size_t>(cloud->points_in));
  cloud->points_m.reserve(static_cast<size_t>(cloud->points_in));
  if (rgb || intensity) cloud->colors.reserve(static_cast<size_t>(cloud->points_in));

  for (uint32_t row = 0; row < layout.height; ++row) {
    const uint8_t* row_start = data + static_cast<size_t>(row) * layout.row_step;
    for (uint32_t column = 0; column < layout.width; ++column) {
      const uint8_t* point = row_start + static_cast<size_t>(column) * layout.point_step;
      float x, y, z;
      std::memcpy(&x, point + x_offset, 4);
      std::memcpy(&y, point + y_offset, 4);
      std::memcpy(&z, point + z_offset, 4);
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
        ++cloud->dropped_non_finite;
        continue;
      }
      cloud->points_m.emplace_back(x, y, z);
      if (times.has_times()) cloud->point_times_s.push_back(times.time_s(point, column));
      if (rgb) {
        cloud->colors.push_back(packed_color(point + rgb->offset));
      } else if (intensity) {
        cloud->colors.push_back(
            grey_of(point + intensity->offset, intensity->datatype, grey_scale));
      }
    }
  }
  return CloudDecodeResult{};
}

}  // namespace io
}  // namespace covox

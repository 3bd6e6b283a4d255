#pragma once
// Per-point times of a PointCloud2, shared by the ROS layer's decoder (pointcloud_fields.h) and
// the bag reader (rosbag_messages.h), in seconds after the cloud's stamp: a `t` field (Ouster
// drivers: nanoseconds from the scan's start), else a `time` field (Velodyne drivers: seconds),
// each of any numeric type; else, for an organised cloud (height > 1), the column order: column c
// of w fired at c / w of `column_sweep_duration_s`. Clouds without any of these have no times.
#include <cstdint>
#include <string>
#include <vector>

namespace covox {
namespace io {

enum class PointTimeSource { kNone, kNanosecondsField, kSecondsField, kColumnOrder };
const char* to_string(PointTimeSource source);

class PointTimeReader {
 public:
  PointTimeReader() = default;
  // `names`, `offsets` and `datatypes` describe the cloud's fields, in one order.
  PointTimeReader(const std::vector<std::string>& names, const std::vector<uint32_t>& offsets,
                  const std::vector<uint8_t>& datatypes, uint32_t width, uint32_t height,
                  double column_sweep_duration_s);

  PointTimeSource source() const { return source_; }
  bool has_times() const { return source_ != PointTimeSource::kNone; }
  // The field read (empty for the column order or none), for checks of the cloud's layout.
  const std::string& field_name() const { return field_name_; }
  // The time of the point whose bytes start at `point`, in column `column` of its row.
  float time_s(const uint8_t* point, uint32_t column) const;

 private:
  PointTimeSource source_ = PointTimeSource::kNone;
  std::string field_name_;
  uint32_t offset_ = 0;
  uint8_t datatype_ = 0;
  double seconds_per_unit_ = 0.0;  // field units, or one column, in seconds
};

// Every field's name, offset and datatype as PointTimeReader takes them, from any field type with
// those members (the ROS layer's and the bag reader's).
template <class Field>
PointTimeReader make_point_time_reader(const std::vector<Field>& fields, uint32_t width,
                                       uint32_t height, double column_sweep_duration_s) {
  std::vector<std::string> names;
  std::vector<uint32_t> offsets;
  std::vector<uint8_t> datatypes;
  for (const Field& field : fields) {
    names.push_back(field.name);
    offsets.push_back(field.offset);
    datatypes.push_back(field.datatype);
  }
  return PointTimeReader(names, offsets, datatypes, width, height, column_sweep_duration_s);
}

}  // namespace io
}  // namespace covox

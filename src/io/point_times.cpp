#include "covoxslam/io/point_times.h"

#include "covoxslam/io/point_field_types.h"

namespace covox {
namespace io {

const char* to_string(PointTimeSource source) {
  switch (source) {
    case PointTimeSource::kNone:
      return "none";
    case PointTimeSource::kNanosecondsField:
      return "field t (ns)";
    case PointTimeSource::kSecondsField:
      return "field time (s)";
    case PointTimeSource::kColumnOrder:
      return "column order";
  }
  return "unknown";
}

PointTimeReader::PointTimeReader(const std::vector<std::string>& names,
                                 const std::vector<uint32_t>& offsets,
                                 const std::vector<uint8_t>& datatypes, uint32_t width,
                                 uint32_t height, double column_sweep_duration_s) {
  // `t` before `time`: a cloud with both is an Ouster cloud with an extra field.
  const struct {
    const char* name;
    PointTimeSource source;
    double seconds_per_unit;
  } kFields[] = {{"t", PointTimeSource::kNanosecondsField, 1e-9},
                 {"time", PointTimeSource::kSecondsField, 1.0}};
  for (const auto& wanted : kFields) {
    for (size_t i = 0; i < names.size(); ++i) {
      if (names[i] != wanted.name || point_field_type_size(datatypes[i]) == 0) continue;
      source_ = wanted.source;
      field_name_ = names[i];
      offset_ = offsets[i];
      datatype_ = datatypes[i];
      seconds_per_unit_ = wanted.seconds_per_unit;
      return;
    }
  }
  if (height > 1 && width > 1 && column_sweep_duration_s > 0.0) {
    source_ = PointTimeSource::kColumnOrder;
    seconds_per_unit_ = column_sweep_duration_s / width;
  }
}

float PointTimeReader::time_s(const uint8_t* point, uint32_t column) const {
  switch (source_) {
    case PointTimeSource::kNanosecondsField:
    case PointTimeSource::kSecondsField:
      return static_cast<float>(read_point_field_element(point + offset_, datatype_) *
                                seconds_per_unit_);
    case PointTimeSource::kColumnOrder:
      return static_cast<float>(column * seconds_per_unit_);
    case PointTimeSource::kNone:
      break;
  }
  return 0.0f;
}

}  // namespace io
}  // namespace covox

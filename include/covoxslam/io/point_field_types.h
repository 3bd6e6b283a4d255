#pragma once
// sensor_msgs/PointField datatypes, shared by the two readers of PointCloud2 bytes: the ROS
// layer's cloud decoder (pointcloud_fields.h) and the bag reader (rosbag_messages.h).
#include <cstddef>
#include <cstdint>

namespace covox {
namespace io {

// The datatype codes of sensor_msgs/PointField. Unscoped because a field's datatype is a plain
// uint8_t in the message: the codes compare with it and initialise it without casts.
enum PointFieldType : uint8_t {
  kInt8 = 1,
  kUint8 = 2,
  kInt16 = 3,
  kUint16 = 4,
  kInt32 = 5,
  kUint32 = 6,
  kFloat32 = 7,
  kFloat64 = 8,
};

// Bytes of one element of `datatype` (a PointField code); 0 for an unknown code.
size_t point_field_type_size(uint8_t datatype);

// One element of a numeric field at `at` as a double; 0 for an unknown code. The data is
// little-endian (callers refuse big-endian clouds) and read with memcpy, because the fields of a
// foreign cloud need not be aligned.
double read_point_field_element(const uint8_t* at, uint8_t datatype);

}  // namespace io
}  // namespace covox

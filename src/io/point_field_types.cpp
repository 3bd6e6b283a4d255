#include "covoxslam/io/point_field_types.h"

#include <cstring>

namespace covox {
namespace io {
namespace {

template <class T>
double load_as_double(const uint8_t* at) {
  T value;
  std::memcpy(&value, at, sizeof(T));
  return static_cast<double>(value);
}

}  // namespace

size_t point_field_type_size(uint8_t datatype) {
  switch (datatype) {
    case kInt8:
    case kUint8:
      return 1;
    case kInt16:
    case kUint16:
      return 2;
    case kInt32:
    case kUint32:
    case kFloat32:
      return 4;
    case kFloat64:
      return 8;
    default:
      return 0;
  }
}

double read_point_field_element(const uint8_t* at, uint8_t datatype) {
  switch (datatype) {
    case kInt8:
      return load_as_double<int8_t>(at);
    case kUint8:
      return load_as_double<uint8_t>(at);
    case kInt16:
      return load_as_double<int16_t>(at);
    case kUint16:
      return load_as_double<uint16_t>(at);
    case kInt32:
      return load_as_double<int32_t>(at);
    case kUint32:
      return load_as_double<uint32_t>(at);
    case kFloat32:
      return load_as_double<float>(at);
    case kFloat64:
      return load_as_double<double>(at);
    default:
      return 0.0;
  }
}

}  // namespace io
}  // namespace covox

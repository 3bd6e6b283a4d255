#include "covoxslam/io/rosbag_bytes.h"

#include <cmath>
#include <cstring>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace rosbag {

// The bag format is little-endian; so are x86-64 and aarch64 (every target of this project), so
// values are copied byte for byte. A big-endian host would need swaps here and nowhere else.
static_assert(sizeof(float) == 4 && sizeof(double) == 8, "IEEE 754 float and double expected");

namespace {

// The value whose bytes start at `at` (memcpy: a field inside a message need not be aligned).
template <class T>
T copy_value(const uint8_t* at) {
  T value;
  std::memcpy(&value, at, sizeof(T));
  return value;
}

}  // namespace

RosTime RosTime::from_seconds(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0.0 || seconds >= 4294967296.0) {
    throw Error("ROS time " + std::to_string(seconds) + " s is outside [0, 2^32) s");
  }
  const uint64_t nanoseconds = static_cast<uint64_t>(std::llround(seconds * 1e9));
  RosTime time;
  time.sec = static_cast<uint32_t>(nanoseconds / 1000000000ull);
  time.nsec = static_cast<uint32_t>(nanoseconds % 1000000000ull);
  return time;
}

void ByteWriter::u32(uint32_t value) { bytes(&value, 4); }
void ByteWriter::u64(uint64_t value) { bytes(&value, 8); }
void ByteWriter::f32(float value) { bytes(&value, 4); }
void ByteWriter::f64(double value) { bytes(&value, 8); }

void ByteWriter::string(const std::string& value) {
  u32(static_cast<uint32_t>(value.size()));
  bytes(value.data(), value.size());
}

void ByteWriter::bytes(const void* data, size_t size) {
  const uint8_t* first = static_cast<const uint8_t*>(data);
  out_->insert(out_->end(), first, first + size);
}

void ByteReader::need(size_t size, const char* field) const {
  if (size > size_ - position_) {
    throw Error(what_ + ": truncated while reading " + field + " (needs " + std::to_string(size) +
                " bytes at offset " + std::to_string(position_) + ", " +
                std::to_string(size_ - position_) + " left)");
  }
}

uint8_t ByteReader::u8(const char* field) {
  need(1, field);
  return data_[position_++];
}

uint32_t ByteReader::u32(const char* field) { return copy_value<uint32_t>(bytes(4, field)); }
uint64_t ByteReader::u64(const char* field) { return copy_value<uint64_t>(bytes(8, field)); }
float ByteReader::f32(const char* field) { return copy_value<float>(bytes(4, field)); }
double ByteReader::f64(const char* field) { return copy_value<double>(bytes(8, field)); }

RosTime ByteReader::time(const char* field) {
  RosTime value;
  value.sec = u32(field);
  value.nsec = u32(field);
  return value;
}

std::string ByteReader::string(const char* field) {
  const uint32_t length = u32(field);
  const uint8_t* first = bytes(length, field);
  return std::string(reinterpret_cast<const char*>(first), length);
}

const uint8_t* ByteReader::bytes(size_t size, const char* field) {
  need(size, field);
  const uint8_t* first = data_ + position_;
  position_ += size;
  return first;
}

}  // namespace rosbag
}  // namespace io
}  // namespace covox

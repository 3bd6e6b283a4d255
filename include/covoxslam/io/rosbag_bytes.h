#pragma once
// Little-endian encoding as ROS 1 uses it, both in bag records and in serialised messages:
// integers and IEEE floats in little-endian byte order, strings and variable-length arrays as a
// uint32 length followed by the bytes, `time` as uint32 seconds then uint32 nanoseconds.
//
// ByteReader checks every read against the end of its buffer and throws covox::Error naming
// what it was reading, so a truncated or corrupt bag is reported instead of read past its end.
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace covox {
namespace io {
namespace rosbag {

// A ROS time: seconds and nanoseconds since the epoch (or since whatever the bag counts from).
struct RosTime {
  uint32_t sec = 0;
  uint32_t nsec = 0;

  // Rounds to the nearest nanosecond; throws covox::Error for a negative or non-finite time or
  // one past 2^32 s, which ROS 1 cannot store.
  static RosTime from_seconds(double seconds);
  double to_seconds() const { return sec + 1e-9 * nsec; }
  uint64_t to_nanoseconds() const { return uint64_t(sec) * 1000000000ull + nsec; }
  bool operator<(const RosTime& other) const { return to_nanoseconds() < other.to_nanoseconds(); }
  bool operator==(const RosTime& other) const { return sec == other.sec && nsec == other.nsec; }
};

class ByteWriter {
 public:
  explicit ByteWriter(std::vector<uint8_t>* out) : out_(out) {}
  void u8(uint8_t value) { out_->push_back(value); }
  void u32(uint32_t value);
  void u64(uint64_t value);
  void i32(int32_t value) { u32(static_cast<uint32_t>(value)); }
  void f32(float value);
  void f64(double value);
  void time(const RosTime& value) {
    u32(value.sec);
    u32(value.nsec);
  }
  // uint32 length, then the bytes.
  void string(const std::string& value);
  void bytes(const void* data, size_t size);
  size_t size() const { return out_->size(); }

 private:
  std::vector<uint8_t>* out_;
};

class ByteReader {
 public:
  // `what` names the buffer in error messages (e.g. "'flight.bag': message on /points").
  ByteReader(const uint8_t* data, size_t size, std::string what)
      : data_(data), size_(size), what_(std::move(what)) {}
  uint8_t u8(const char* field);
  uint32_t u32(const char* field);
  uint64_t u64(const char* field);
  int32_t i32(const char* field) { return static_cast<int32_t>(u32(field)); }
  float f32(const char* field);
  double f64(const char* field);
  RosTime time(const char* field);
  std::string string(const char* field);
  // A pointer to the next `size` bytes, which are skipped.
  const uint8_t* bytes(size_t size, const char* field);
  size_t position() const { return position_; }
  size_t remaining() const { return size_ - position_; }
  const std::string& what() const { return what_; }

 private:
  void need(size_t size, const char* field) const;
  const uint8_t* data_;
  size_t size_;
  size_t position_ = 0;
  std::string what_;
};

}  // namespace rosbag
}  // namespace io
}  // namespace covox

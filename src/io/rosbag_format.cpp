#include "covoxslam/io/rosbag_format.h"

#include <cstring>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace rosbag {
namespace {

template <class T>
std::string raw_bytes(const T& value) {
  return std::string(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <class T>
T value_of(const std::string& bytes, const std::string& name, const std::string& what) {
  if (bytes.size() != sizeof(T)) {
    throw Error(what + ": record header field '" + name + "' has " + std::to_string(bytes.size()) +
                " bytes, expected " + std::to_string(sizeof(T)));
  }
  T value;
  std::memcpy(&value, bytes.data(), sizeof(T));
  return value;
}

}  // namespace

void RecordHeader::set_u8(const std::string& name, uint8_t value) {
  fields_[name] = raw_bytes(value);
}
void RecordHeader::set_u32(const std::string& name, uint32_t value) {
  fields_[name] = raw_bytes(value);
}
void RecordHeader::set_u64(const std::string& name, uint64_t value) {
  fields_[name] = raw_bytes(value);
}
void RecordHeader::set_time(const std::string& name, const RosTime& value) {
  fields_[name] = raw_bytes(value.sec) + raw_bytes(value.nsec);
}

const std::string& RecordHeader::text(const std::string& name, const std::string& what) const {
  const auto found = fields_.find(name);
  if (found == fields_.end()) throw Error(what + ": record header has no field '" + name + "'");
  return found->second;
}

uint8_t RecordHeader::u8(const std::string& name, const std::string& what) const {
  return value_of<uint8_t>(text(name, what), name, what);
}
uint32_t RecordHeader::u32(const std::string& name, const std::string& what) const {
  return value_of<uint32_t>(text(name, what), name, what);
}
uint64_t RecordHeader::u64(const std::string& name, const std::string& what) const {
  return value_of<uint64_t>(text(name, what), name, what);
}
RosTime RecordHeader::time(const std::string& name, const std::string& what) const {
  const std::string& bytes = text(name, what);
  if (bytes.size() != 8)
    throw Error(what + ": record header field '" + name + "' is not an 8-byte time");
  RosTime value;
  std::memcpy(&value.sec, bytes.data(), 4);
  std::memcpy(&value.nsec, bytes.data() + 4, 4);
  return value;
}

void RecordHeader::encode(ByteWriter& out) const {
  for (const auto& field : fields_) {
    out.u32(static_cast<uint32_t>(field.first.size() + 1 + field.second.size()));
    out.bytes(field.first.data(), field.first.size());
    out.u8('=');
    out.bytes(field.second.data(), field.second.size());
  }
}

RecordHeader RecordHeader::decode(const uint8_t* data, size_t size, const std::string& what) {
  ByteReader in(data, size, what);
  RecordHeader header;
  while (in.remaining() > 0) {
    const uint32_t length = in.u32("header field length");
    const char* field = reinterpret_cast<const char*>(in.bytes(length, "header field"));
    const void* equals = std::memchr(field, '=', length);
    if (equals == nullptr) throw Error(what + ": record header field without '='");
    const size_t name_size = static_cast<const char*>(equals) - field;
    header.fields_[std::string(field, name_size)] =
        std::string(field + name_size + 1, length - name_size - 1);
  }
  return header;
}

void append_record(std::vector<uint8_t>* out, const RecordHeader& header, const uint8_t* data,
                   size_t data_size) {
  ByteWriter writer(out);
  const size_t length_at = out->size();
  writer.u32(0);  // patched below, once the header's size is known
  header.encode(writer);
  const uint32_t header_size = static_cast<uint32_t>(out->size() - length_at - 4);
  std::memcpy(out->data() + length_at, &header_size, 4);
  writer.u32(static_cast<uint32_t>(data_size));
  writer.bytes(data, data_size);
}

}  // namespace rosbag
}  // namespace io
}  // namespace covox

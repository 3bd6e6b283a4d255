#pragma once
// The record layer of the ROS bag format 2.0, shared by BagWriter and BagReader (the file's
// layout: kBagMagic below). A record is: uint32 header length, header, uint32 data length, data.
// A header is a sequence of fields, each uint32 length then "name=value" with a binary value; the
// field "op" says the record's kind.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "covoxslam/io/rosbag_bytes.h"

namespace covox {
namespace io {
namespace rosbag {

// A bag file:
//   "#ROSBAG V2.0\n"
//   bag header record, padded to 4096 bytes (index_pos, conn_count, chunk_count)
//   per chunk: chunk record (connection and message-data records, uncompressed or compressed
//              as one lz4 or bz2 stream; BagWriter writes them uncompressed),
//              then one index-data record per connection in the chunk (stamp and offset of
//              each of its messages inside the chunk)
//   at index_pos: every connection record, then one chunk-info record per chunk
constexpr char kBagMagic[] = "#ROSBAG V2.0\n";
constexpr size_t kBagMagicSize = 13;
constexpr size_t kBagHeaderRecordSize = 4096;  // rosbag pads the bag header so it can be rewritten

enum RecordOp : uint8_t {
  kOpMessageData = 0x02,
  kOpBagHeader = 0x03,
  kOpIndexData = 0x04,
  kOpChunk = 0x05,
  kOpChunkInfo = 0x06,
  kOpConnection = 0x07,
};

// Header fields by name, values as raw bytes.
class RecordHeader {
 public:
  void set(const std::string& name, const std::string& value) { fields_[name] = value; }
  void set_u8(const std::string& name, uint8_t value);
  void set_u32(const std::string& name, uint32_t value);
  void set_u64(const std::string& name, uint64_t value);
  void set_time(const std::string& name, const RosTime& value);

  bool has(const std::string& name) const { return fields_.count(name) != 0; }
  // Each throws covox::Error naming `what` when the field is missing or has the wrong size.
  const std::string& text(const std::string& name, const std::string& what) const;
  uint8_t u8(const std::string& name, const std::string& what) const;
  uint32_t u32(const std::string& name, const std::string& what) const;
  uint64_t u64(const std::string& name, const std::string& what) const;
  RosTime time(const std::string& name, const std::string& what) const;

  // Fields in name order (deterministic bytes).
  void encode(ByteWriter& out) const;
  static RecordHeader decode(const uint8_t* data, size_t size, const std::string& what);

 private:
  std::map<std::string, std::string> fields_;
};

// Appends a whole record (lengths, header, data) to `out`.
void append_record(std::vector<uint8_t>* out, const RecordHeader& header, const uint8_t* data,
                   size_t data_size);

}  // namespace rosbag
}  // namespace io
}  // namespace covox

#pragma once
// Writes ROS bag format 2.0 files without ROS, so that the simulator runs where ROS is absent:
// uncompressed chunks, index-data records after each chunk, and the connection and chunk-info
// index at the end, so `rosbag info`, `rosbag play` and the rosbag C++/Python APIs read the file
// as one that `rosbag record` wrote. The bag is written as "<path>.active" (rosbag record's name
// for a bag in progress) and renamed into place by close(): a run cut short never leaves a bag
// that looks complete. The bytes depend only on what is written (no wall-clock time, no host
// name), so equal input gives an equal file.
#include <cstdint>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "covoxslam/io/rosbag_bytes.h"
#include "covoxslam/io/rosbag_format.h"
#include "covoxslam/io/rosbag_messages.h"

namespace covox {
namespace io {
namespace rosbag {

//   rosbag::BagWriter bag("flight.bag");
//   const uint32_t points = bag.add_connection("/points", rosbag::point_cloud2_type());
//   bag.write(points, stamp, rosbag::serialize(cloud));
//   bag.close();
class BagWriter {
 public:
  // A chunk is closed once its data exceeds `chunk_threshold_bytes` (rosbag record's default).
  // Throws covox::Error when the file cannot be created.
  explicit BagWriter(const std::string& path, size_t chunk_threshold_bytes = 768 * 1024);
  ~BagWriter();  // without close(): the partial ".active" file is removed
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  // A topic with its message type; returns the connection id for write(). `latching` marks
  // topics such as /tf_static whose last message every late subscriber must get (rosbag play
  // republishes them latched).
  uint32_t add_connection(const std::string& topic, const MessageType& type, bool latching = false);
  // Appends one serialised message. Times must not decrease (per connection): readers binary
  // search the index. Throws covox::Error for an unknown connection, a decreasing time or an
  // I/O failure.
  void write(uint32_t connection, const RosTime& time, const std::vector<uint8_t>& serialized);
  // Flushes the last chunk, writes the index, rewrites the bag header and renames the file into
  // place. Idempotent. Throws covox::Error on I/O failure.
  void close();

  uint64_t message_count() const { return message_count_; }

 private:
  struct Connection {
    std::string topic;
    const MessageType* type = nullptr;
    bool latching = false;
    bool written = false;  // its connection record is in some chunk already
    RosTime last_time;
  };
  struct IndexEntry {
    RosTime time;
    uint32_t offset;  // of the message record in the chunk's data
  };
  struct ChunkInfo {
    uint64_t position = 0;
    RosTime start, end;
    std::map<uint32_t, uint32_t> counts;  // connection -> messages
  };

  std::vector<uint8_t> connection_record(uint32_t id) const;
  void flush_chunk();
  void append_to_file(const std::vector<uint8_t>& bytes);

  std::string path_, active_path_;
  size_t chunk_threshold_bytes_;
  std::ofstream file_;
  uint64_t file_position_ = 0;
  std::vector<Connection> connections_;
  std::vector<uint8_t> chunk_data_;
  std::map<uint32_t, std::vector<IndexEntry>> chunk_index_;
  RosTime chunk_start_, chunk_end_;
  std::vector<ChunkInfo> chunks_;
  uint64_t message_count_ = 0;
  bool closed_ = false;
};

}  // namespace rosbag
}  // namespace io
}  // namespace covox

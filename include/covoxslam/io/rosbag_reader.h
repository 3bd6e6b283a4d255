#pragma once
// Reads ROS bag format 2.0 files without ROS: the connections and the message index at open,
// then any message by random access. Chunks must be uncompressed (`rosbag decompress` converts a
// bz2 or lz4 bag); an unindexed bag (recording cut short) is refused with the fix in the message
// (`rosbag reindex`).
//
//   rosbag::BagReader bag("flight.bag");
//   for (const rosbag::IndexEntry& entry : bag.index({"/tf", "/tf_static"})) {
//     const rosbag::BagMessage message = bag.read(entry);
//     ... rosbag::parse_tf_message(message.data.data(), message.data.size(), ...)
//   }
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "covoxslam/io/rosbag_bytes.h"

namespace covox {
namespace io {
namespace rosbag {

struct BagConnection {
  uint32_t id = 0;
  std::string topic;
  std::string type;  // e.g. "sensor_msgs/PointCloud2"
  std::string md5sum;
  std::string message_definition;
  std::string callerid;
  bool latching = false;
};

// Where one message lies.
struct IndexEntry {
  RosTime time;
  uint32_t connection = 0;
  uint32_t chunk = 0;   // index into the bag's chunks
  uint32_t offset = 0;  // of the message record inside the chunk's data
};

struct BagMessage {
  RosTime time;
  const BagConnection* connection = nullptr;
  std::vector<uint8_t> data;  // the serialised message
};

class BagReader {
 public:
  // Reads the bag header, the connections and every chunk's index. Throws covox::Error naming the
  // file for a missing file, another format or version, an unindexed bag, compressed chunks or a
  // truncated or corrupt index.
  explicit BagReader(const std::string& path);

  const std::string& path() const { return path_; }
  const std::vector<BagConnection>& connections() const { return connections_; }
  // The connection with this id; throws covox::Error when there is none.
  const BagConnection& connection(uint32_t id) const;
  // Messages on `topic` (all its connections); 0 for an unknown topic.
  uint64_t message_count(const std::string& topic) const;
  uint64_t message_count() const { return entries_.size(); }
  // Time of the first and the last message (both zero for an empty bag).
  RosTime start_time() const;
  RosTime end_time() const;

  // Every message on `topics` (all messages when empty), ordered by time and, at equal times, by
  // position in the file (the order they were written).
  std::vector<IndexEntry> index(const std::vector<std::string>& topics = {}) const;
  // The message an index entry points to. Throws covox::Error for a corrupt record.
  BagMessage read(const IndexEntry& entry);

 private:
  struct Chunk {
    uint64_t data_position = 0;  // first byte of the chunk's data in the file
    uint32_t data_size = 0;
  };
  void read_index();
  // Reads one record at `position`: its header and (unless `data` is null) its data; returns the
  // position after the record.
  uint64_t read_record(uint64_t position, std::vector<uint8_t>* header, std::vector<uint8_t>* data);

  std::string path_;
  std::ifstream file_;
  uint64_t file_size_ = 0;
  std::vector<BagConnection> connections_;
  std::vector<Chunk> chunks_;
  std::vector<IndexEntry> entries_;  // every message, in index() order
};

}  // namespace rosbag
}  // namespace io
}  // namespace covox

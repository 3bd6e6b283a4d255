#pragma once
// Reads ROS bag format 2.0 files without ROS: the connections and the message index at open,
// then any message by random access. Chunks may be uncompressed or compressed with lz4 or bz2
// (`rosbag record --lz4`, `--bz2`, `rosbag compress`; see io/internal/rosbag_chunk_codecs.h): a
// compressed chunk is decompressed whole when one of its messages is read and kept until a
// message of another chunk is read, so reading in time order decompresses each chunk once. A
// build without liblz4 or libbz2 refuses such bags at open, naming the library. An unindexed bag
// (recording cut short) is refused with the fix in the message (`rosbag reindex`).
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

//   rosbag::BagReader bag("flight.bag");
//   for (const rosbag::IndexEntry& entry : bag.index({"/tf", "/tf_static"})) {
//     const rosbag::BagMessage message = bag.read(entry);
//     ... rosbag::parse_tf_message(message.data.data(), message.data.size(), ...)
//   }
class BagReader {
 public:
  // Reads the bag header, the connections and every chunk's index. Throws covox::Error naming the
  // file for a missing file, another format or version, an unindexed bag, chunks compressed in a
  // way this build cannot read, or a truncated or corrupt index.
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
  // The message an index entry points to. Throws covox::Error for a corrupt record or chunk.
  BagMessage read(const IndexEntry& entry);

 private:
  struct Chunk {
    std::string compression;     // "none", "lz4" or "bz2"
    uint64_t position = 0;       // of the chunk record in the file
    uint64_t data_position = 0;  // first byte of the chunk's data in the file
    uint64_t stored_size = 0;    // bytes of the chunk's data in the file
    uint32_t data_size = 0;      // bytes of its records, once decompressed
  };
  static constexpr uint32_t kNoChunk = ~uint32_t(0);
  void read_index();
  // The decompressed records of compressed chunk `number` (cached: the last chunk asked for).
  const std::vector<uint8_t>& decompressed_chunk(uint32_t number);
  // Reads the record an index entry points to; returns its description for error messages.
  std::string read_message_record(const IndexEntry& entry, std::vector<uint8_t>* header,
                                  std::vector<uint8_t>* data);
  // Reads one record at `position`: its header and (unless `data` is null) its data; returns the
  // position after the record.
  uint64_t read_record(uint64_t position, std::vector<uint8_t>* header, std::vector<uint8_t>* data);

  std::string path_;
  std::ifstream file_;
  uint64_t file_size_ = 0;
  std::vector<BagConnection> connections_;
  std::vector<Chunk> chunks_;
  std::vector<IndexEntry> entries_;  // every message, in index() order
  uint32_t cached_chunk_ = kNoChunk;
  std::vector<uint8_t> cached_chunk_data_;
};

}  // namespace rosbag
}  // namespace io
}  // namespace covox

#include "covoxslam/io/rosbag_writer.h"

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace rosbag {
namespace {

// The bag header record: where the index starts and how many connections and chunks it lists,
// padded with spaces to kBagHeaderRecordSize bytes so that close() can rewrite it in place.
std::vector<uint8_t> bag_header_record(uint64_t index_position, uint32_t connections,
                                       uint32_t chunks) {
  RecordHeader header;
  header.set_u8("op", kOpBagHeader);
  header.set_u64("index_pos", index_position);
  header.set_u32("conn_count", connections);
  header.set_u32("chunk_count", chunks);
  std::vector<uint8_t> encoded;
  ByteWriter writer(&encoded);
  header.encode(writer);
  const std::vector<uint8_t> padding(kBagHeaderRecordSize - 8 - encoded.size(), ' ');
  std::vector<uint8_t> record;
  append_record(&record, header, padding.data(), padding.size());
  return record;
}

// Appends a record whose data is `entries` one after another, each written by `write_entry`
// (the index-data and chunk-info records are such lists).
template <class Entries, class WriteEntry>
void append_record_of_entries(std::vector<uint8_t>* out, const RecordHeader& header,
                              const Entries& entries, WriteEntry&& write_entry) {
  std::vector<uint8_t> data;
  ByteWriter writer(&data);
  for (const auto& entry : entries) write_entry(writer, entry);
  append_record(out, header, data.data(), data.size());
}

}  // namespace

BagWriter::BagWriter(const std::string& path, size_t chunk_threshold_bytes)
    : path_(path), active_path_(path + ".active"), chunk_threshold_bytes_(chunk_threshold_bytes) {
  file_.open(active_path_, std::ios::binary | std::ios::trunc);
  if (!file_) throw Error("cannot create bag '" + active_path_ + "': " + std::strerror(errno));
  std::vector<uint8_t> start(kBagMagic, kBagMagic + kBagMagicSize);
  const std::vector<uint8_t> header = bag_header_record(0, 0, 0);
  start.insert(start.end(), header.begin(), header.end());
  append_to_file(start);
}

BagWriter::~BagWriter() {
  if (!closed_) {
    file_.close();
    std::remove(active_path_.c_str());
  }
}

uint32_t BagWriter::add_connection(const std::string& topic, const MessageType& type,
                                   bool latching) {
  if (closed_) throw Error("bag '" + path_ + "': add_connection after close");
  Connection connection;
  connection.topic = topic;
  connection.type = &type;
  connection.latching = latching;
  connections_.push_back(connection);
  return static_cast<uint32_t>(connections_.size() - 1);
}

std::vector<uint8_t> BagWriter::connection_record(uint32_t id) const {
  const Connection& connection = connections_[id];
  RecordHeader header;
  header.set_u8("op", kOpConnection);
  header.set_u32("conn", id);
  header.set("topic", connection.topic);
  // The data is a connection header as a ROS publisher sends it.
  RecordHeader publisher;
  publisher.set("topic", connection.topic);
  publisher.set("type", connection.type->name);
  publisher.set("md5sum", connection.type->md5sum);
  publisher.set("message_definition", connection.type->definition);
  publisher.set("callerid", "/covoxslam");
  if (connection.latching) publisher.set("latching", "1");
  std::vector<uint8_t> data;
  ByteWriter writer(&data);
  publisher.encode(writer);
  std::vector<uint8_t> record;
  append_record(&record, header, data.data(), data.size());
  return record;
}

void BagWriter::write(uint32_t connection_id, const RosTime& time,
                      const std::vector<uint8_t>& serialized) {
  if (closed_) throw Error("bag '" + path_ + "': write after close");
  if (connection_id >= connections_.size()) {
    throw Error("bag '" + path_ + "': unknown connection " + std::to_string(connection_id));
  }
  Connection& connection = connections_[connection_id];
  if (time < connection.last_time) {
    throw Error("bag '" + path_ + "': time " + std::to_string(time.to_seconds()) + " s on " +
                connection.topic + " is before the previous message's " +
                std::to_string(connection.last_time.to_seconds()) + " s");
  }
  connection.last_time = time;
  if (!connection.written) {
    const std::vector<uint8_t> record = connection_record(connection_id);
    chunk_data_.insert(chunk_data_.end(), record.begin(), record.end());
    connection.written = true;
  }
  if (chunk_index_.empty()) {
    chunk_start_ = time;
    chunk_end_ = time;
  }
  if (time < chunk_start_) chunk_start_ = time;
  if (chunk_end_ < time) chunk_end_ = time;
  chunk_index_[connection_id].push_back({time, static_cast<uint32_t>(chunk_data_.size())});
  RecordHeader header;
  header.set_u8("op", kOpMessageData);
  header.set_u32("conn", connection_id);
  header.set_time("time", time);
  append_record(&chunk_data_, header, serialized.data(), serialized.size());
  ++message_count_;
  if (chunk_data_.size() >= chunk_threshold_bytes_) flush_chunk();
}

void BagWriter::flush_chunk() {
  if (chunk_data_.empty()) return;
  ChunkInfo info;
  info.position = file_position_;
  info.start = chunk_start_;
  info.end = chunk_end_;
  std::vector<uint8_t> bytes;
  RecordHeader header;
  header.set_u8("op", kOpChunk);
  header.set("compression", "none");
  header.set_u32("size", static_cast<uint32_t>(chunk_data_.size()));
  append_record(&bytes, header, chunk_data_.data(), chunk_data_.size());
  for (const auto& entry : chunk_index_) {
    RecordHeader index_header;
    index_header.set_u8("op", kOpIndexData);
    index_header.set_u32("ver", 1);
    index_header.set_u32("conn", entry.first);
    index_header.set_u32("count", static_cast<uint32_t>(entry.second.size()));
    append_record_of_entries(&bytes, index_header, entry.second,
                             [](ByteWriter& writer, const IndexEntry& message) {
                               writer.time(message.time);
                               writer.u32(message.offset);
                             });
    info.counts[entry.first] = static_cast<uint32_t>(entry.second.size());
  }
  append_to_file(bytes);
  chunks_.push_back(info);
  chunk_data_.clear();
  chunk_index_.clear();
}

void BagWriter::close() {
  if (closed_) return;
  flush_chunk();
  const uint64_t index_position = file_position_;
  std::vector<uint8_t> bytes;
  uint32_t written_connections = 0;
  for (uint32_t id = 0; id < connections_.size(); ++id) {
    // A connection without messages never entered a chunk; listing it would make readers look
    // for it in none.
    if (!connections_[id].written) continue;
    const std::vector<uint8_t> record = connection_record(id);
    bytes.insert(bytes.end(), record.begin(), record.end());
    ++written_connections;
  }
  for (const ChunkInfo& chunk : chunks_) {
    RecordHeader header;
    header.set_u8("op", kOpChunkInfo);
    header.set_u32("ver", 1);
    header.set_u64("chunk_pos", chunk.position);
    header.set_time("start_time", chunk.start);
    header.set_time("end_time", chunk.end);
    header.set_u32("count", static_cast<uint32_t>(chunk.counts.size()));
    append_record_of_entries(&bytes, header, chunk.counts,
                             [](ByteWriter& writer, const auto& connection_count) {
                               writer.u32(connection_count.first);   // connection id
                               writer.u32(connection_count.second);  // its messages in the chunk
                             });
  }
  append_to_file(bytes);
  const std::vector<uint8_t> header =
      bag_header_record(index_position, written_connections, static_cast<uint32_t>(chunks_.size()));
  file_.seekp(static_cast<std::streamoff>(kBagMagicSize));
  file_.write(reinterpret_cast<const char*>(header.data()),
              static_cast<std::streamsize>(header.size()));
  file_.close();
  if (!file_) throw Error("writing bag '" + active_path_ + "' failed: " + std::strerror(errno));
  if (std::rename(active_path_.c_str(), path_.c_str()) != 0) {
    throw Error("cannot rename '" + active_path_ + "' to '" + path_ + "': " + std::strerror(errno));
  }
  closed_ = true;
}

void BagWriter::append_to_file(const std::vector<uint8_t>& bytes) {
  file_.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
  if (!file_) throw Error("writing bag '" + active_path_ + "' failed: " + std::strerror(errno));
  file_position_ += bytes.size();
}

}  // namespace rosbag
}  // namespace io
}  // namespace covox

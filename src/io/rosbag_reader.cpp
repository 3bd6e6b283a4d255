#include "covoxslam/io/rosbag_reader.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <set>

#include "covoxslam/core/error.h"
#include "covoxslam/io/internal/rosbag_chunk_codecs.h"
#include "covoxslam/io/rosbag_format.h"

namespace covox {
namespace io {
namespace rosbag {

BagReader::BagReader(const std::string& path) : path_(path) {
  file_.open(path, std::ios::binary);
  if (!file_) throw Error("cannot open bag '" + path + "': " + std::strerror(errno));
  file_.seekg(0, std::ios::end);
  file_size_ = static_cast<uint64_t>(file_.tellg());
  file_.seekg(0);
  char magic[kBagMagicSize] = {};
  file_.read(magic, kBagMagicSize);
  if (!file_ || std::memcmp(magic, kBagMagic, kBagMagicSize) != 0) {
    const std::string start(magic, std::find(magic, magic + kBagMagicSize, '\n'));
    if (start.rfind("#ROSBAG", 0) == 0) {
      throw Error("'" + path + "' is a '" + start +
                  "' bag; only format 2.0 is supported (`rosbag fix` converts)");
    }
    throw Error("'" + path + "' is not a ROS bag (no '#ROSBAG V2.0' at its start)");
  }
  read_index();
}

uint64_t BagReader::read_record(uint64_t position, std::vector<uint8_t>* header,
                                std::vector<uint8_t>* data) {
  const std::string what = "bag '" + path_ + "' at byte " + std::to_string(position);
  auto read_length = [&](uint64_t at, const char* field) {
    if (at + 4 > file_size_)
      throw Error(what + ": truncated (" + field + " past the end of the file)");
    file_.seekg(static_cast<std::streamoff>(at));
    uint32_t length = 0;
    file_.read(reinterpret_cast<char*>(&length), 4);
    if (!file_) throw Error(what + ": read failed");
    if (at + 4 + length > file_size_)
      throw Error(what + ": truncated (" + field + " runs past the end of the file)");
    return length;
  };
  const uint32_t header_size = read_length(position, "record header");
  header->resize(header_size);
  file_.read(reinterpret_cast<char*>(header->data()), header_size);
  const uint64_t data_at = position + 4 + header_size;
  const uint32_t data_size = read_length(data_at, "record data");
  if (data != nullptr) {
    data->resize(data_size);
    file_.read(reinterpret_cast<char*>(data->data()), data_size);
  }
  if (!file_) throw Error(what + ": read failed");
  return data_at + 4 + data_size;
}

// A connection record: its header names the connection and topic, its data is the publisher's
// header (message type, checksum, definition, caller, latching).
static BagConnection decode_connection(const RecordHeader& header, const std::vector<uint8_t>& data,
                                       const std::string& what) {
  const RecordHeader publisher = RecordHeader::decode(data.data(), data.size(), what);
  BagConnection connection;
  connection.id = header.u32("conn", what);
  connection.topic = header.text("topic", what);
  connection.type = publisher.text("type", what);
  connection.md5sum = publisher.text("md5sum", what);
  connection.message_definition =
      publisher.has("message_definition") ? publisher.text("message_definition", what) : "";
  connection.callerid = publisher.has("callerid") ? publisher.text("callerid", what) : "";
  connection.latching = publisher.has("latching") && publisher.text("latching", what) == "1";
  return connection;
}

void BagReader::read_index() {
  std::vector<uint8_t> header_bytes, data;
  read_record(kBagMagicSize, &header_bytes, nullptr);
  const std::string what = "bag '" + path_ + "'";
  const RecordHeader bag_header =
      RecordHeader::decode(header_bytes.data(), header_bytes.size(), what + " header");
  if (bag_header.u8("op", what) != kOpBagHeader)
    throw Error(what + ": the first record is not a bag header");
  const uint64_t index_position = bag_header.u64("index_pos", what);
  const uint32_t connection_count = bag_header.u32("conn_count", what);
  const uint32_t chunk_count = bag_header.u32("chunk_count", what);
  if (index_position == 0) {
    throw Error(what + " has no index (its recording was cut short?): run `rosbag reindex` on it");
  }

  std::map<uint32_t, size_t> connection_slot;
  uint64_t position = index_position;
  for (uint32_t i = 0; i < connection_count; ++i) {
    position = read_record(position, &header_bytes, &data);
    const std::string record_what = what + " connection record";
    const RecordHeader header =
        RecordHeader::decode(header_bytes.data(), header_bytes.size(), record_what);
    if (header.u8("op", record_what) != kOpConnection)
      throw Error(what + ": expected a connection record in the index");
    const BagConnection connection = decode_connection(header, data, record_what);
    connection_slot[connection.id] = connections_.size();
    connections_.push_back(connection);
  }

  struct ChunkInfo {
    uint64_t position;
    uint32_t connections;
  };
  std::vector<ChunkInfo> infos;
  for (uint32_t i = 0; i < chunk_count; ++i) {
    position = read_record(position, &header_bytes, nullptr);
    const std::string record_what = what + " chunk info record";
    const RecordHeader header =
        RecordHeader::decode(header_bytes.data(), header_bytes.size(), record_what);
    if (header.u8("op", record_what) != kOpChunkInfo)
      throw Error(what + ": expected a chunk info record in the index");
    infos.push_back({header.u64("chunk_pos", record_what), header.u32("count", record_what)});
  }

  for (const ChunkInfo& info : infos) {
    const std::string chunk_what = what + " chunk at byte " + std::to_string(info.position);
    position = read_record(info.position, &header_bytes, nullptr);
    const RecordHeader header =
        RecordHeader::decode(header_bytes.data(), header_bytes.size(), chunk_what);
    if (header.u8("op", chunk_what) != kOpChunk) throw Error(chunk_what + ": not a chunk record");
    Chunk chunk;
    chunk.compression = header.text("compression", chunk_what);
    const std::string problem = chunk_compression_problem(chunk.compression);
    if (!problem.empty()) {
      throw Error(chunk_what + " is compressed with '" + chunk.compression + "': " + problem +
                  ", or run `rosbag decompress` on the bag");
    }
    chunk.data_size = header.u32("size", chunk_what);
    chunk.position = info.position;
    chunk.data_position = info.position + 4 + header_bytes.size() + 4;
    chunk.stored_size = position - chunk.data_position;
    const uint32_t chunk_number = static_cast<uint32_t>(chunks_.size());
    chunks_.push_back(chunk);
    // The chunk's index-data records follow it, one per connection it holds.
    for (uint32_t c = 0; c < info.connections; ++c) {
      position = read_record(position, &header_bytes, &data);
      const RecordHeader index =
          RecordHeader::decode(header_bytes.data(), header_bytes.size(), chunk_what + " index");
      if (index.u8("op", chunk_what) != kOpIndexData)
        throw Error(chunk_what + ": expected an index-data record after it");
      if (index.u32("ver", chunk_what) != 1)
        throw Error(chunk_what + ": unsupported index-data version");
      const uint32_t connection = index.u32("conn", chunk_what);
      if (connection_slot.count(connection) == 0)
        throw Error(chunk_what + ": index names unknown connection " + std::to_string(connection));
      const uint32_t count = index.u32("count", chunk_what);
      ByteReader in(data.data(), data.size(), chunk_what + " index");
      for (uint32_t m = 0; m < count; ++m) {
        IndexEntry entry;
        entry.time = in.time("index time");
        entry.offset = in.u32("index offset");
        entry.connection = connection;
        entry.chunk = chunk_number;
        if (entry.offset >= chunk.data_size)
          throw Error(chunk_what + ": index offset past the chunk's end");
        entries_.push_back(entry);
      }
    }
  }
  std::stable_sort(entries_.begin(), entries_.end(), [](const IndexEntry& a, const IndexEntry& b) {
    if (!(a.time == b.time)) return a.time < b.time;
    if (a.chunk != b.chunk) return a.chunk < b.chunk;
    return a.offset < b.offset;
  });
}

const BagConnection& BagReader::connection(uint32_t id) const {
  for (const BagConnection& connection : connections_) {
    if (connection.id == id) return connection;
  }
  throw Error("bag '" + path_ + "' has no connection " + std::to_string(id));
}

uint64_t BagReader::message_count(const std::string& topic) const { return index({topic}).size(); }

RosTime BagReader::start_time() const {
  return entries_.empty() ? RosTime() : entries_.front().time;
}
RosTime BagReader::end_time() const { return entries_.empty() ? RosTime() : entries_.back().time; }

std::vector<IndexEntry> BagReader::index(const std::vector<std::string>& topics) const {
  if (topics.empty()) return entries_;
  std::set<uint32_t> wanted;
  for (const BagConnection& connection : connections_) {
    if (std::find(topics.begin(), topics.end(), connection.topic) != topics.end())
      wanted.insert(connection.id);
  }
  std::vector<IndexEntry> selected;
  for (const IndexEntry& entry : entries_) {
    if (wanted.count(entry.connection) != 0) selected.push_back(entry);
  }
  return selected;
}

const std::vector<uint8_t>& BagReader::decompressed_chunk(uint32_t number) {
  if (number == cached_chunk_) return cached_chunk_data_;
  const Chunk& chunk = chunks_[number];
  const std::string what = "bag '" + path_ + "' chunk at byte " + std::to_string(chunk.position);
  std::vector<uint8_t> stored(chunk.stored_size);
  file_.seekg(static_cast<std::streamoff>(chunk.data_position));
  file_.read(reinterpret_cast<char*>(stored.data()), static_cast<std::streamsize>(stored.size()));
  if (!file_) throw Error(what + ": read failed");
  cached_chunk_ = kNoChunk;  // until the new data is complete
  cached_chunk_data_ =
      decompress_chunk(chunk.compression, stored.data(), stored.size(), chunk.data_size, what);
  cached_chunk_ = number;
  return cached_chunk_data_;
}

std::string BagReader::read_message_record(const IndexEntry& entry, std::vector<uint8_t>* header,
                                           std::vector<uint8_t>* data) {
  const Chunk& chunk = chunks_[entry.chunk];
  if (chunk.compression == "none") {
    const uint64_t position = chunk.data_position + entry.offset;
    const uint64_t end = read_record(position, header, data);
    const std::string what = "bag '" + path_ + "' message at byte " + std::to_string(position);
    if (end > chunk.data_position + chunk.data_size)
      throw Error(what + ": runs past the end of its chunk");
    return what;
  }
  // A compressed chunk is decompressed whole; the index's offsets count in its decompressed data.
  const std::string what = "bag '" + path_ + "' message at byte " + std::to_string(entry.offset) +
                           " of the " + chunk.compression + " chunk at byte " +
                           std::to_string(chunk.position);
  const std::vector<uint8_t>& bytes = decompressed_chunk(entry.chunk);
  ByteReader in(bytes.data(), bytes.size(), what);
  in.bytes(entry.offset, "the chunk's records before the message");
  const uint32_t header_size = in.u32("record header length");
  const uint8_t* header_bytes = in.bytes(header_size, "record header");
  header->assign(header_bytes, header_bytes + header_size);
  const uint32_t data_size = in.u32("record data length (the record runs past its chunk)");
  const uint8_t* data_bytes = in.bytes(data_size, "record data (the record runs past its chunk)");
  data->assign(data_bytes, data_bytes + data_size);
  return what;
}

BagMessage BagReader::read(const IndexEntry& entry) {
  if (entry.chunk >= chunks_.size())
    throw Error("bag '" + path_ + "': index entry names chunk " + std::to_string(entry.chunk));
  std::vector<uint8_t> header_bytes;
  BagMessage message;
  const std::string what = read_message_record(entry, &header_bytes, &message.data);
  const RecordHeader header = RecordHeader::decode(header_bytes.data(), header_bytes.size(), what);
  if (header.u8("op", what) != kOpMessageData)
    throw Error(what + ": the index points at something else than a message");
  if (header.u32("conn", what) != entry.connection)
    throw Error(what + ": connection differs from the index");
  message.time = header.time("time", what);
  message.connection = &connection(entry.connection);
  return message;
}

}  // namespace rosbag
}  // namespace io
}  // namespace covox

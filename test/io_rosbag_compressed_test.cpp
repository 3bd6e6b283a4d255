// Compressed ROS bags: copies of a bag compressed by ROS's own `rosbag compress --lz4` and
// `--bz2` (the independent writer of the compressed format) read back, through our reader, the
// very bytes, stamps and topics that were written, in order and in any order; a damaged compressed
// chunk and an unknown compression are clear errors. Where `rosbag compress` is not installed or
// this build has no liblz4 / libbz2, the checks that need them skip with a message.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/io/internal/rosbag_chunk_codecs.h"
#include "covoxslam/io/rosbag_messages.h"
#include "covoxslam/io/rosbag_reader.h"
#include "covoxslam/io/rosbag_writer.h"

namespace covox {
namespace io {
namespace rosbag {
namespace {

namespace fs = std::filesystem;

std::vector<uint8_t> file_bytes(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(file),
                              std::istreambuf_iterator<char>());
}

void write_file(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  file.write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

size_t find_bytes(const std::vector<uint8_t>& bytes, const std::string& text, size_t from = 0) {
  const auto at = std::search(bytes.begin() + from, bytes.end(), text.begin(), text.end());
  return at == bytes.end() ? std::string::npos : static_cast<size_t>(at - bytes.begin());
}

struct WrittenMessage {
  std::string topic;
  RosTime time;
  std::vector<uint8_t> data;
};

// A bag of about 2 MB (several of rosbag's 768 kB chunks once compressed): clouds of
// pseudo-random points between tf messages, every message at its own stamp.
std::vector<WrittenMessage> write_flight_bag(const std::string& path) {
  std::vector<WrittenMessage> written;
  BagWriter bag(path, 64 * 1024);
  const uint32_t statics = bag.add_connection("/tf_static", tf_message_type(), true);
  const uint32_t tf = bag.add_connection("/tf", tf_message_type());
  const uint32_t clouds = bag.add_connection("/points", point_cloud2_type());
  auto write = [&](uint32_t connection, const std::string& topic, RosTime time,
                   std::vector<uint8_t> data) {
    bag.write(connection, time, data);
    written.push_back({topic, time, std::move(data)});
  };
  TfMessage lever;
  lever.transforms.resize(1);
  lever.transforms[0].header.frame_id = "imu";
  lever.transforms[0].child_frame_id = "lidar";
  lever.transforms[0].T_parent_child.translation() = Eigen::Vector3d(0.03, 0.0, 0.08);
  write(statics, "/tf_static", RosTime{100, 0}, serialize(lever));
  uint32_t state = 12345;
  for (uint32_t k = 0; k < 60; ++k) {
    TfMessage odometry = lever;
    odometry.transforms[0].header.stamp = RosTime{100, 1000 + 2000000 * k};
    odometry.transforms[0].header.frame_id = "odom";
    odometry.transforms[0].child_frame_id = "imu";
    odometry.transforms[0].T_parent_child.translation() = Eigen::Vector3d(0.1 * k, 0.0, 1.0);
    write(tf, "/tf", odometry.transforms[0].header.stamp, serialize(odometry));
    Header header;
    header.seq = k;
    header.stamp = RosTime{100, 2000 + 2000000 * k};
    header.frame_id = "lidar";
    std::vector<Eigen::Vector3f> points(2500 + 10 * k);
    for (Eigen::Vector3f& p : points) {
      for (int axis = 0; axis < 3; ++axis) {
        state = state * 1664525u + 1013904223u;
        p[axis] = static_cast<float>(state >> 8) * 1e-5f - 80.0f;
      }
    }
    write(clouds, "/points", header.stamp, serialize(make_point_cloud2(header, points)));
  }
  bag.close();
  return written;
}

// Every message of `bag`, read in `order` of its index, equals what was written.
void expect_messages(BagReader& bag, const std::vector<WrittenMessage>& written,
                     bool reverse_order) {
  const std::vector<IndexEntry> index = bag.index();
  ASSERT_EQ(index.size(), written.size()) << bag.path();
  for (size_t n = 0; n < index.size(); ++n) {
    const size_t i = reverse_order ? index.size() - 1 - n : n;
    const BagMessage message = bag.read(index[i]);
    EXPECT_EQ(message.connection->topic, written[i].topic) << bag.path() << " message " << i;
    EXPECT_EQ(message.time, written[i].time) << bag.path() << " message " << i;
    EXPECT_TRUE(message.data == written[i].data) << bag.path() << " message " << i << " differs";
  }
}

// `rosbag compress --<compression>` of `source` into `folder`; false when ROS's tool is missing.
bool rosbag_compress(const std::string& source, const std::string& compression,
                     const std::string& folder) {
  if (!fs::exists("/usr/bin/rosbag") ||
      std::system("/usr/bin/python3 -c 'import rosbag' > /dev/null 2>&1") != 0) {
    return false;
  }
  fs::create_directories(folder);
  const std::string command = "/usr/bin/rosbag compress -q --" + compression +
                              " --output-dir=" + folder + " " + source + " > /dev/null 2>&1";
  EXPECT_EQ(std::system(command.c_str()), 0) << command;
  return true;
}

class CompressedBag : public ::testing::TestWithParam<const char*> {};

TEST_P(CompressedBag, ReadsTheBytesRosbagCompressed) {
  const std::string compression = GetParam();
  const std::string problem = chunk_compression_problem(compression);
  if (!problem.empty()) GTEST_SKIP() << compression << " chunks: " << problem;
  const std::string source = ::testing::TempDir() + "/io_rosbag_" + compression + "_source.bag";
  const std::string folder = ::testing::TempDir() + "/io_rosbag_" + compression;
  const std::vector<WrittenMessage> written = write_flight_bag(source);
  if (!rosbag_compress(source, compression, folder)) {
    GTEST_SKIP() << "ROS's `rosbag compress` is not installed (apt install python3-rosbag): "
                    "no independently compressed bag to read";
  }
  const std::string compressed = folder + "/io_rosbag_" + compression + "_source.bag";
  // The copy really is compressed, in the stream format the decoder expects.
  const std::vector<uint8_t> bytes = file_bytes(compressed);
  EXPECT_EQ(find_bytes(bytes, "compression=none"), std::string::npos);
  const size_t chunk = find_bytes(bytes, "compression=" + compression);
  ASSERT_NE(chunk, std::string::npos);
  const std::string magic = compression == "lz4" ? std::string("\x04\x22\x4d\x18") : "BZh";
  const size_t stream = find_bytes(bytes, magic, chunk);
  ASSERT_NE(stream, std::string::npos) << "no " << compression << " stream after the chunk header";
  EXPECT_LT(bytes.size(), file_bytes(source).size());

  BagReader original(source);
  BagReader bag(compressed);
  EXPECT_EQ(bag.message_count(), original.message_count());
  EXPECT_EQ(bag.message_count("/points"), 60u);
  expect_messages(original, written, /*reverse_order=*/false);
  expect_messages(bag, written, /*reverse_order=*/false);
  // Backwards: each read may need another chunk than the one decompressed before.
  expect_messages(bag, written, /*reverse_order=*/true);
  for (const BagConnection& connection : bag.connections()) {
    if (connection.topic == "/points") {
      EXPECT_EQ(connection.md5sum, point_cloud2_type().md5sum);
      EXPECT_EQ(connection.type, "sensor_msgs/PointCloud2");
    }
    if (connection.topic == "/tf_static") EXPECT_TRUE(connection.latching);
  }

  // A damaged byte inside the compressed stream is found (lz4 frames and bz2 streams carry
  // checksums) and named; it never comes back as a message.
  std::vector<uint8_t> damaged = bytes;
  damaged[stream + 2000] ^= 0x5a;
  const std::string damaged_path = folder + "/damaged.bag";
  write_file(damaged_path, damaged);
  BagReader damaged_bag(damaged_path);
  try {
    for (const IndexEntry& entry : damaged_bag.index()) damaged_bag.read(entry);
    FAIL() << "a damaged " << compression << " chunk was read without an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("corrupt " + compression + " chunk"),
              std::string::npos)
        << error.what();
  }
  fs::remove_all(folder);
  fs::remove(source);
}

INSTANTIATE_TEST_SUITE_P(RosbagFile, CompressedBag, ::testing::Values("lz4", "bz2"));

TEST(RosbagFile, UnknownChunkCompressionIsAClearError) {
  const std::string path = ::testing::TempDir() + "/io_rosbag_zstd.bag";
  write_flight_bag(path);
  std::vector<uint8_t> bytes = file_bytes(path);
  // Same length as "none", so the record layout stays valid.
  const std::string none = "compression=none", other = "compression=zstd";
  for (size_t at = find_bytes(bytes, none); at != std::string::npos;
       at = find_bytes(bytes, none, at + 1)) {
    std::copy(other.begin(), other.end(), bytes.begin() + static_cast<std::ptrdiff_t>(at));
  }
  write_file(path, bytes);
  try {
    BagReader bag(path);
    FAIL() << "a bag with zstd chunks was opened";
  } catch (const Error& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("compressed with 'zstd'"), std::string::npos) << message;
    EXPECT_NE(message.find("unknown compression"), std::string::npos) << message;
    EXPECT_NE(message.find("rosbag decompress"), std::string::npos) << message;
  }
  EXPECT_EQ(chunk_compression_problem("none"), "");
  fs::remove(path);
}

}  // namespace
}  // namespace rosbag
}  // namespace io
}  // namespace covox

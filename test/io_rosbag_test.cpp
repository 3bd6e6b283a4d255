// ROS bags without ROS: messages serialise to the bytes ROS 1 uses (checked field by field
// against hand-assembled little-endian bytes), bags round-trip through our writer and reader
// across many chunks, bad input is a clear error, the tf buffer interpolates like tf2, and -
// where ROS's python rosbag is installed - ROS itself reads our bags with the right topics,
// types, counts and values (the independent check of the format, MD5 sums and definitions).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/io/rosbag_messages.h"
#include "covoxslam/io/rosbag_reader.h"
#include "covoxslam/io/rosbag_tf_buffer.h"
#include "covoxslam/io/rosbag_writer.h"

namespace covox {
namespace io {
namespace rosbag {
namespace {

Eigen::Isometry3d pose_of(const Eigen::Vector3d& translation, double yaw_rad,
                          double roll_rad = 0.0) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitX()))
                      .toRotationMatrix();
  pose.translation() = translation;
  return pose;
}

std::vector<uint8_t> file_bytes(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(file),
                              std::istreambuf_iterator<char>());
}

TEST(RosbagMessages, PointStampedBytesAreTheRos1Layout) {
  PointStampedMessage message;
  message.header.seq = 7;
  message.header.stamp = RosTime{1000, 250000000};
  message.header.frame_id = "enu";
  message.point = Eigen::Vector3d(1.5, -2.0, 0.25);
  const std::vector<uint8_t> bytes = serialize(message);
  // seq, sec, nsec, length-prefixed "enu", three float64: 4 + 4 + 4 + 4 + 3 + 24 bytes.
  ASSERT_EQ(bytes.size(), 43u);
  uint32_t u;
  std::memcpy(&u, &bytes[0], 4);
  EXPECT_EQ(u, 7u);
  std::memcpy(&u, &bytes[4], 4);
  EXPECT_EQ(u, 1000u);
  std::memcpy(&u, &bytes[8], 4);
  EXPECT_EQ(u, 250000000u);
  std::memcpy(&u, &bytes[12], 4);
  EXPECT_EQ(u, 3u);
  EXPECT_EQ(std::string(bytes.begin() + 16, bytes.begin() + 19), "enu");
  double y;
  std::memcpy(&y, &bytes[27], 8);
  EXPECT_EQ(y, -2.0);
  // Little-endian: the least significant byte of seq comes first.
  EXPECT_EQ(bytes[0], 7);
  const PointStampedMessage parsed = parse_point_stamped(bytes.data(), bytes.size(), "test");
  EXPECT_EQ(parsed.header.frame_id, "enu");
  EXPECT_EQ(parsed.header.stamp, message.header.stamp);
  EXPECT_EQ(parsed.point, message.point);
}

TEST(RosbagMessages, TfOdometryAndCloudRoundTrip) {
  TfMessage tf;
  for (int i = 0; i < 3; ++i) {
    TransformStamped transform;
    transform.header.stamp = RosTime{10, static_cast<uint32_t>(i)};
    transform.header.frame_id = "odom";
    transform.child_frame_id = "frame" + std::to_string(i);
    transform.T_parent_child = pose_of(Eigen::Vector3d(i, 2.0 * i, -1.0), 0.3 * i, 0.1);
    tf.transforms.push_back(transform);
  }
  const std::vector<uint8_t> tf_bytes = serialize(tf);
  const TfMessage tf_back = parse_tf_message(tf_bytes.data(), tf_bytes.size(), "tf");
  ASSERT_EQ(tf_back.transforms.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(tf_back.transforms[i].child_frame_id, tf.transforms[i].child_frame_id);
    EXPECT_TRUE(
        tf_back.transforms[i].T_parent_child.isApprox(tf.transforms[i].T_parent_child, 1e-12));
  }

  OdometryMessage odometry;
  odometry.header.frame_id = "odom";
  odometry.child_frame_id = "base_link";
  odometry.T_parent_child = pose_of(Eigen::Vector3d(4, 5, 6), -1.0);
  odometry.pose_covariance[35] = 0.5;
  odometry.linear_velocity = Eigen::Vector3d(1, 0, 0);
  odometry.twist_covariance[0] = 2.0;
  const std::vector<uint8_t> odometry_bytes = serialize(odometry);
  // Header (4+8+4+4) + child (4+9) + pose (56) + covariance (288) + twist (48) + covariance (288).
  EXPECT_EQ(odometry_bytes.size(), 20u + 13u + 56u + 288u + 48u + 288u);
  const OdometryMessage odometry_back =
      parse_odometry(odometry_bytes.data(), odometry_bytes.size(), "odometry");
  EXPECT_TRUE(odometry_back.T_parent_child.isApprox(odometry.T_parent_child, 1e-12));
  EXPECT_EQ(odometry_back.pose_covariance[35], 0.5);
  EXPECT_EQ(odometry_back.twist_covariance[0], 2.0);
  EXPECT_EQ(odometry_back.linear_velocity, odometry.linear_velocity);

  // A message of one type is not silently read as another.
  EXPECT_THROW(parse_point_stamped(odometry_bytes.data(), odometry_bytes.size(), "x"), Error);
  EXPECT_THROW(parse_tf_message(tf_bytes.data(), tf_bytes.size() - 3, "x"), Error);

  Header header;
  header.frame_id = "os1_lidar";
  const std::vector<Eigen::Vector3f> points = {{1, 2, 3}, {-4, 5.5f, 6}, {0, 0, 1e3f}};
  const PointCloud2Message cloud = make_point_cloud2(header, points, {10.0f, 20.0f, 30.0f});
  const std::vector<uint8_t> cloud_bytes = serialize(cloud);
  const PointCloud2Message cloud_back =
      parse_point_cloud2(cloud_bytes.data(), cloud_bytes.size(), "cloud");
  EXPECT_EQ(cloud_back.point_step, 16u);
  EXPECT_EQ(cloud_back.fields.size(), 4u);
  const PointCloud extracted = extract_points(cloud_back, "cloud");
  ASSERT_EQ(extracted.size(), 3u);
  for (size_t i = 0; i < 3; ++i) EXPECT_EQ(extracted.points_m[i], points[i]);
  EXPECT_EQ(extracted.intensities[2], 30.0f);
}

TEST(RosbagMessages, ForeignCloudLayoutsAreReadAndBadOnesAreClearErrors) {
  // An Ouster-like organised cloud: float64 z before float32 x and y, a uint16 intensity, padding,
  // a row step with slack, and a missing return marked NaN.
  PointCloud2Message cloud;
  cloud.height = 2;
  cloud.width = 2;
  cloud.fields = {{"z", 0, kFloat64, 1},
                  {"x", 8, kFloat32, 1},
                  {"y", 12, kFloat32, 1},
                  {"intensity", 16, kUint16, 1}};
  cloud.point_step = 24;
  cloud.row_step = 56;
  cloud.data.assign(cloud.height * cloud.row_step, 0);
  auto put = [&](int row, int column, double x, double y, double z, uint16_t intensity) {
    uint8_t* p = cloud.data.data() + row * cloud.row_step + column * cloud.point_step;
    const float xf = static_cast<float>(x), yf = static_cast<float>(y);
    std::memcpy(p, &z, 8);
    std::memcpy(p + 8, &xf, 4);
    std::memcpy(p + 12, &yf, 4);
    std::memcpy(p + 16, &intensity, 2);
  };
  put(0, 0, 1, 2, 3, 100);
  put(0, 1, std::nan(""), 0, 0, 0);
  put(1, 0, 4, 5, 6, 200);
  put(1, 1, -7, -8, -9, 300);
  ReadStats stats;
  const PointCloud points = extract_points(cloud, "ouster", &stats);
  ASSERT_EQ(points.size(), 3u);
  EXPECT_EQ(stats.dropped_non_finite_points, 1u);
  EXPECT_EQ(points.points_m[1], Eigen::Vector3f(4, 5, 6));
  EXPECT_EQ(points.points_m[2], Eigen::Vector3f(-7, -8, -9));
  EXPECT_EQ(points.intensities[2], 300.0f);

  PointCloud2Message no_z = cloud;
  no_z.fields.erase(no_z.fields.begin());
  EXPECT_THROW(extract_points(no_z, "no z"), Error);
  PointCloud2Message short_step = cloud;
  short_step.point_step = 14;  // y would end at byte 16
  EXPECT_THROW(extract_points(short_step, "short step"), Error);
  PointCloud2Message short_data = cloud;
  short_data.data.resize(60);
  EXPECT_THROW(extract_points(short_data, "short data"), Error);
  PointCloud2Message big_endian = cloud;
  big_endian.is_bigendian = true;
  EXPECT_THROW(extract_points(big_endian, "big endian"), Error);
  try {
    extract_points(no_z, "cloud on /points");
    FAIL();
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("cloud on /points"), std::string::npos);
  }
}

// A bag with three topics over many small chunks; returns what was written per topic.
struct WrittenBag {
  std::vector<double> cloud_stamps_s, tf_stamps_s, fix_stamps_s;
};

WrittenBag write_test_bag(const std::string& path, size_t chunk_threshold_bytes) {
  WrittenBag written;
  BagWriter bag(path, chunk_threshold_bytes);
  const uint32_t statics = bag.add_connection("/tf_static", tf_message_type(), true);
  const uint32_t tf = bag.add_connection("/tf", tf_message_type());
  const uint32_t clouds = bag.add_connection("/points", point_cloud2_type());
  const uint32_t fixes = bag.add_connection("/fix", point_stamped_type());
  bag.add_connection("/never_used", odometry_type());
  TfMessage static_tf;
  TransformStamped lever;
  lever.header.stamp = RosTime{100, 0};
  lever.header.frame_id = "imu";
  lever.child_frame_id = "lidar";
  lever.T_parent_child = pose_of(Eigen::Vector3d(0, 0, 0.1), M_PI);
  static_tf.transforms.push_back(lever);
  bag.write(statics, RosTime{100, 0}, serialize(static_tf));
  for (int k = 0; k < 20; ++k) {
    const double stamp_s = 100.0 + 0.1 * k;
    const RosTime stamp = RosTime::from_seconds(stamp_s);
    TfMessage odom;
    TransformStamped transform;
    transform.header.stamp = stamp;
    transform.header.frame_id = "odom";
    transform.child_frame_id = "imu";
    transform.T_parent_child = pose_of(Eigen::Vector3d(k, 0.5 * k, 1.0), 0.05 * k);
    odom.transforms.push_back(transform);
    bag.write(tf, stamp, serialize(odom));
    written.tf_stamps_s.push_back(stamp_s);
    Header header;
    header.seq = k;
    header.stamp = stamp;
    header.frame_id = "lidar";
    std::vector<Eigen::Vector3f> points(50 + k, Eigen::Vector3f(k, 1, 2));
    bag.write(clouds, stamp, serialize(make_point_cloud2(header, points)));
    written.cloud_stamps_s.push_back(stamp_s);
    if (k % 2 == 0) {
      PointStampedMessage fix;
      fix.header.stamp = stamp;
      fix.header.frame_id = "enu";
      fix.point = Eigen::Vector3d(k, -k, 0.5);
      bag.write(fixes, stamp, serialize(fix));
      written.fix_stamps_s.push_back(stamp_s);
    }
  }
  bag.close();
  return written;
}

TEST(RosbagFile, RoundTripAcrossManyChunks) {
  const std::string path = ::testing::TempDir() + "/io_rosbag_round_trip.bag";
  const WrittenBag written = write_test_bag(path, 2000);  // a few messages per chunk
  BagReader bag(path);
  EXPECT_EQ(bag.message_count("/points"), written.cloud_stamps_s.size());
  EXPECT_EQ(bag.message_count("/tf"), written.tf_stamps_s.size());
  EXPECT_EQ(bag.message_count("/fix"), written.fix_stamps_s.size());
  EXPECT_EQ(bag.message_count("/tf_static"), 1u);
  EXPECT_EQ(bag.message_count("/never_used"), 0u);
  EXPECT_EQ(bag.connections().size(), 4u);  // the unused connection is not listed
  EXPECT_NEAR(bag.start_time().to_seconds(), 100.0, 1e-9);
  EXPECT_NEAR(bag.end_time().to_seconds(), 101.9, 1e-9);
  for (const BagConnection& connection : bag.connections()) {
    if (connection.topic == "/tf_static") {
      EXPECT_TRUE(connection.latching);
    }
    if (connection.topic == "/points") {
      EXPECT_EQ(connection.type, "sensor_msgs/PointCloud2");
      EXPECT_EQ(connection.md5sum, "1158d486dd51d683ce2f1be655c3c181");
      EXPECT_FALSE(connection.latching);
    }
  }
  // Messages come back in time order, each with its content.
  const std::vector<IndexEntry> clouds = bag.index({"/points"});
  ASSERT_EQ(clouds.size(), 20u);
  for (size_t k = 0; k < clouds.size(); ++k) {
    const BagMessage message = bag.read(clouds[k]);
    EXPECT_EQ(message.connection->topic, "/points");
    EXPECT_NEAR(message.time.to_seconds(), written.cloud_stamps_s[k], 1e-9);
    const PointCloud2Message cloud =
        parse_point_cloud2(message.data.data(), message.data.size(), "cloud");
    EXPECT_EQ(cloud.header.seq, k);
    EXPECT_EQ(cloud.width, 50 + k);
    EXPECT_EQ(extract_points(cloud, "cloud").points_m.back().x(), static_cast<float>(k));
  }
  const std::vector<IndexEntry> all = bag.index();
  EXPECT_EQ(all.size(), bag.message_count());
  for (size_t i = 1; i < all.size(); ++i) EXPECT_FALSE(all[i].time < all[i - 1].time);
  // Chunking changes the layout, not the content.
  const std::string one_chunk_path = ::testing::TempDir() + "/io_rosbag_one_chunk.bag";
  write_test_bag(one_chunk_path, 1 << 30);
  BagReader one_chunk(one_chunk_path);
  EXPECT_EQ(one_chunk.message_count(), bag.message_count());
  EXPECT_LT(file_bytes(one_chunk_path).size(), file_bytes(path).size());
  std::remove(path.c_str());
  std::remove(one_chunk_path.c_str());
}

TEST(RosbagFile, WriterIsDeterministicAndRefusesTimeGoingBack) {
  const std::string path = ::testing::TempDir() + "/io_rosbag_determinism.bag";
  write_test_bag(path, 3000);
  const std::vector<uint8_t> first = file_bytes(path);
  write_test_bag(path, 3000);
  EXPECT_TRUE(first == file_bytes(path));
  BagWriter bag(path);
  const uint32_t fixes = bag.add_connection("/fix", point_stamped_type());
  bag.write(fixes, RosTime{5, 0}, serialize(PointStampedMessage()));
  EXPECT_THROW(bag.write(fixes, RosTime{4, 999999999}, serialize(PointStampedMessage())), Error);
  EXPECT_THROW(bag.write(17, RosTime{6, 0}, {}), Error);
  std::remove(path.c_str());
}

TEST(RosbagFile, BadFilesAreClearErrors) {
  const std::string path = ::testing::TempDir() + "/io_rosbag_bad.bag";
  EXPECT_THROW(BagReader(::testing::TempDir() + "/no_such_file.bag"), Error);
  {
    std::ofstream file(path, std::ios::binary);
    file << "#ROSBAG V1.2\nold bag";
  }
  try {
    BagReader bag(path);
    FAIL();
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("V1.2"), std::string::npos);
  }
  write_test_bag(path, 2000);
  std::vector<uint8_t> bytes = file_bytes(path);
  // Cut in the index: the bag header points past the end.
  {
    std::ofstream file(path, std::ios::binary | std::ios::trunc);
    file.write(reinterpret_cast<const char*>(bytes.data()), bytes.size() - 100);
  }
  EXPECT_THROW(BagReader bag(path), Error);
  // An unindexed bag (index_pos 0, as a recording cut short leaves it) names the fix.
  write_test_bag(path, 2000);
  bytes = file_bytes(path);
  const std::string field = "index_pos=";
  auto at = std::search(bytes.begin(), bytes.end(), field.begin(), field.end());
  ASSERT_NE(at, bytes.end());
  std::fill(at + field.size(), at + field.size() + 8, 0);
  {
    std::ofstream file(path, std::ios::binary | std::ios::trunc);
    file.write(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  }
  try {
    BagReader bag(path);
    FAIL();
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("reindex"), std::string::npos);
  }
  std::remove(path.c_str());
}

TEST(RosbagTfBuffer, ChainsStaticAndInterpolatedTransformsLikeTf2) {
  TfBuffer tf;
  const Eigen::Isometry3d T_imu_lidar = pose_of(Eigen::Vector3d(0.1, 0, 0.2), M_PI);
  tf.add("imu", "lidar", 0.0, T_imu_lidar, true);
  const Eigen::Isometry3d a = pose_of(Eigen::Vector3d(0, 0, 1), 0.0);
  const Eigen::Isometry3d b = pose_of(Eigen::Vector3d(2, 4, 1), 0.4);
  tf.add("/odom", "imu", 10.0, a, false);  // a leading slash names the same frame
  tf.add("odom", "imu", 11.0, b, false);
  Eigen::Isometry3d T;
  ASSERT_TRUE(tf.lookup("odom", "lidar", 10.25, &T));
  const Eigen::Isometry3d expected_imu = pose_of(Eigen::Vector3d(0.5, 1.0, 1.0), 0.1);
  EXPECT_TRUE(T.isApprox(expected_imu * T_imu_lidar, 1e-12));
  ASSERT_TRUE(tf.lookup("lidar", "odom", 11.0, &T));
  EXPECT_TRUE(T.isApprox((b * T_imu_lidar).inverse(), 1e-12));
  ASSERT_TRUE(tf.lookup("imu", "lidar", 500.0, &T));  // static only: any time
  EXPECT_TRUE(T.isApprox(T_imu_lidar, 1e-12));
  std::string reason;
  EXPECT_FALSE(tf.lookup("odom", "lidar", 11.01, &T, &reason));
  EXPECT_NE(reason.find("extrapolate"), std::string::npos) << reason;
  EXPECT_FALSE(tf.lookup("odom", "camera", 10.5, &T, &reason));
  EXPECT_NE(reason.find("unknown frame 'camera'"), std::string::npos) << reason;
  tf.add("map", "gps", 0.0, Eigen::Isometry3d::Identity(), true);
  EXPECT_FALSE(tf.lookup("gps", "lidar", 10.5, &T, &reason));
  EXPECT_NE(reason.find("not connected"), std::string::npos) << reason;
  EXPECT_THROW(tf.add("map", "imu", 10.0, a, false), Error);  // a second parent
}

// ROS's own reader is the independent check: topics, types, counts, MD5 sums, and the values
// decoded through our message definitions.
TEST(RosbagFile, RosPythonRosbagReadsOurBag) {
  const char* python = "/usr/bin/python3";
  if (std::system((std::string(python) + " -c 'import rosbag' > /dev/null 2>&1").c_str()) != 0) {
    GTEST_SKIP() << "ROS's python rosbag is not installed (apt install python3-rosbag): skipping "
                    "the check that "
                    "ROS reads our bags";
  }
  const std::string path = ::testing::TempDir() + "/io_rosbag_python.bag";
  write_test_bag(path, 2000);
  const std::string script_path = ::testing::TempDir() + "/io_rosbag_check.py";
  {
    std::ofstream script(script_path);
    script << "import sys, rosbag\n"
              "bag = rosbag.Bag(sys.argv[1])\n"
              "info = bag.get_type_and_topic_info()\n"
              "for topic in sorted(info.topics):\n"
              "    t = info.topics[topic]\n"
              "    print('topic', topic, t.msg_type, t.message_count)\n"
              "for topic, msg_type, md5 in sorted((c.topic, c.datatype, c.md5sum) for c in "
              "bag._connections.values()):\n"
              "    print('md5', topic, md5)\n"
              "last = {}\n"
              "for topic, msg, t in bag.read_messages():\n"
              "    last[topic] = msg\n"
              "c = last['/points']\n"
              "import struct\n"
              "x = struct.unpack_from('<f', bytes(c.data), 0)[0]\n"
              "print('cloud', c.header.frame_id, c.width, c.point_step, [f.name for f in "
              "c.fields], x)\n"
              "f = last['/fix']\n"
              "print('fix', f.header.frame_id, f.point.x, f.point.y, f.point.z)\n"
              "s = last['/tf_static'].transforms[0]\n"
              "print('static', s.header.frame_id, s.child_frame_id, round(s.transform.rotation.z, "
              "9), s.transform.translation.z)\n"
              "o = last['/tf'].transforms[0]\n"
              "print('tf', o.header.frame_id, o.child_frame_id, o.transform.translation.x, "
              "o.header.stamp.to_sec())\n";
  }
  const std::string output_path = ::testing::TempDir() + "/io_rosbag_check.txt";
  const int status = std::system(
      (std::string(python) + " " + script_path + " " + path + " > " + output_path + " 2>&1")
          .c_str());
  std::ifstream output_file(output_path);
  const std::string output((std::istreambuf_iterator<char>(output_file)),
                           std::istreambuf_iterator<char>());
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find("topic /fix geometry_msgs/PointStamped 10\n"), std::string::npos) << output;
  EXPECT_NE(output.find("topic /points sensor_msgs/PointCloud2 20\n"), std::string::npos) << output;
  EXPECT_NE(output.find("topic /tf tf2_msgs/TFMessage 20\n"), std::string::npos) << output;
  EXPECT_NE(output.find("topic /tf_static tf2_msgs/TFMessage 1\n"), std::string::npos) << output;
  EXPECT_NE(output.find("md5 /points 1158d486dd51d683ce2f1be655c3c181"), std::string::npos)
      << output;
  EXPECT_NE(output.find("cloud lidar 69 12 ['x', 'y', 'z'] 19.0"), std::string::npos) << output;
  EXPECT_NE(output.find("fix enu 18.0 -18.0 0.5"), std::string::npos) << output;
  EXPECT_NE(output.find("static imu lidar 1.0 0.1"), std::string::npos) << output;
  EXPECT_NE(output.find("tf odom imu 19.0 101.9"), std::string::npos) << output;
  std::remove(path.c_str());
  std::remove(script_path.c_str());
  std::remove(output_path.c_str());
}

}  // namespace
}  // namespace rosbag
}  // namespace io
}  // namespace covox

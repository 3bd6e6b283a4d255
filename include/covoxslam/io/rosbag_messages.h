#pragma once
// The ROS 1 messages that covoxslam reads from and writes to bags, serialised exactly as ROS 1
// does (rosbag_bytes.h), with their type names, MD5 sums and message definitions for the
// connection headers. The MD5 sums are those of the ROS message files (sensor_msgs, tf2_msgs,
// geometry_msgs, nav_msgs): tools that know the types (rosbag play, rviz) accept our bags, and the
// definitions let tools that do not have the message packages (python rosbag) decode them.
//
//   sensor_msgs/PointCloud2      LiDAR clouds (any field layout when reading)
//   tf2_msgs/TFMessage           /tf and /tf_static
//   geometry_msgs/PointStamped   position-only ground truth (ARCHE's RTK fixes)
//   nav_msgs/Odometry            odometry given as a topic instead of tf
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/io/point_field_types.h"
#include "covoxslam/io/rosbag_bytes.h"
#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {
namespace rosbag {

struct MessageType {
  const char* name;        // e.g. "sensor_msgs/PointCloud2"
  const char* md5sum;      // 32 hex digits
  const char* definition;  // the full text, dependencies included
};

const MessageType& point_cloud2_type();
const MessageType& tf_message_type();
const MessageType& point_stamped_type();
const MessageType& odometry_type();

// std_msgs/Header.
struct Header {
  uint32_t seq = 0;
  RosTime stamp;
  std::string frame_id;
};

struct PointField {
  std::string name;
  uint32_t offset = 0;
  uint8_t datatype = kFloat32;  // a PointFieldType code
  uint32_t count = 1;
};

struct PointCloud2Message {
  Header header;
  uint32_t height = 1;
  uint32_t width = 0;
  std::vector<PointField> fields;
  bool is_bigendian = false;
  uint32_t point_step = 0;
  uint32_t row_step = 0;
  std::vector<uint8_t> data;
  bool is_dense = true;
};

// geometry_msgs/TransformStamped: the pose of child_frame_id in header.frame_id
// (T_parent_child).
struct TransformStamped {
  Header header;
  std::string child_frame_id;
  Eigen::Isometry3d T_parent_child = Eigen::Isometry3d::Identity();
};

struct TfMessage {
  std::vector<TransformStamped> transforms;
};

struct PointStampedMessage {
  Header header;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
};

struct OdometryMessage {
  Header header;
  std::string child_frame_id;
  Eigen::Isometry3d T_parent_child = Eigen::Isometry3d::Identity();  // pose.pose
  std::array<double, 36> pose_covariance{};
  Eigen::Vector3d linear_velocity = Eigen::Vector3d::Zero();   // twist.twist.linear
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // twist.twist.angular
  std::array<double, 36> twist_covariance{};
};

std::vector<uint8_t> serialize(const PointCloud2Message& message);
std::vector<uint8_t> serialize(const TfMessage& message);
std::vector<uint8_t> serialize(const PointStampedMessage& message);
std::vector<uint8_t> serialize(const OdometryMessage& message);

// Each throws covox::Error naming `what` when the bytes are truncated or have bytes left over (a
// message of another type), or hold a non-finite or non-unit quaternion (transforms, odometry).
PointCloud2Message parse_point_cloud2(const uint8_t* data, size_t size, const std::string& what);
TfMessage parse_tf_message(const uint8_t* data, size_t size, const std::string& what);
PointStampedMessage parse_point_stamped(const uint8_t* data, size_t size, const std::string& what);
OdometryMessage parse_odometry(const uint8_t* data, size_t size, const std::string& what);

// A dense (height 1) cloud of float32 x, y, z, plus a float32 intensity field when `intensities`
// is not empty (then it must be as long as `points_m`).
PointCloud2Message make_point_cloud2(const Header& header,
                                     const std::vector<Eigen::Vector3f>& points_m,
                                     const std::vector<float>& intensities = {});

// The points of any PointCloud2 with x, y and z fields (float32 or float64, any offsets, any
// point and row step), plus intensities when it has an `intensity` field of any numeric type, and
// per-point times when it has a time field or is organised (io/point_times.h; organised clouds
// without a time field over `column_sweep_duration_s`, none when 0).
// Points with a non-finite coordinate (Ouster drivers mark missing returns so) are dropped and
// counted in stats->dropped_non_finite_points. Throws covox::Error naming `what` for a cloud
// without x/y/z, a point step or row step too small for its fields, data shorter than
// height * row_step, or big-endian data.
PointCloud extract_points(const PointCloud2Message& cloud, const std::string& what,
                          ReadStats* stats = nullptr, double column_sweep_duration_s = 0.1);

}  // namespace rosbag
}  // namespace io
}  // namespace covox

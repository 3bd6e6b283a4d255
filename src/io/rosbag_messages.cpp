#include "covoxslam/io/rosbag_messages.h"

#include <cmath>
#include <cstring>
#include <initializer_list>

#include "covoxslam/core/error.h"
#include "covoxslam/io/point_times.h"

namespace covox {
namespace io {
namespace rosbag {
namespace {

// The definitions below are the ROS message files without their comments (comments do not enter
// the MD5 sum and decoders ignore them), each dependency after a line of 80 '=' and "MSG: type".
#define COVOX_MSG_SEPARATOR \
  "================================================================================\n"

const char kHeaderDefinition[] =
    "MSG: std_msgs/Header\n"
    "uint32 seq\n"
    "time stamp\n"
    "string frame_id\n";

const char kVector3Definition[] =
    "MSG: geometry_msgs/Vector3\n"
    "float64 x\n"
    "float64 y\n"
    "float64 z\n";

const char kQuaternionDefinition[] =
    "MSG: geometry_msgs/Quaternion\n"
    "float64 x\n"
    "float64 y\n"
    "float64 z\n"
    "float64 w\n";

const char kPointDefinition[] =
    "MSG: geometry_msgs/Point\n"
    "float64 x\n"
    "float64 y\n"
    "float64 z\n";

const std::string kPointCloud2Definition = std::string(
                                               "Header header\n"
                                               "uint32 height\n"
                                               "uint32 width\n"
                                               "PointField[] fields\n"
                                               "bool is_bigendian\n"
                                               "uint32 point_step\n"
                                               "uint32 row_step\n"
                                               "uint8[] data\n"
                                               "bool is_dense\n" COVOX_MSG_SEPARATOR) +
                                           kHeaderDefinition + COVOX_MSG_SEPARATOR +
                                           "MSG: sensor_msgs/PointField\n"
                                           "uint8 INT8    = 1\n"
                                           "uint8 UINT8   = 2\n"
                                           "uint8 INT16   = 3\n"
                                           "uint8 UINT16  = 4\n"
                                           "uint8 INT32   = 5\n"
                                           "uint8 UINT32  = 6\n"
                                           "uint8 FLOAT32 = 7\n"
                                           "uint8 FLOAT64 = 8\n"
                                           "string name\n"
                                           "uint32 offset\n"
                                           "uint8 datatype\n"
                                           "uint32 count\n";

const std::string kTfMessageDefinition =
    std::string("geometry_msgs/TransformStamped[] transforms\n" COVOX_MSG_SEPARATOR
                "MSG: geometry_msgs/TransformStamped\n"
                "Header header\n"
                "string child_frame_id\n"
                "Transform transform\n" COVOX_MSG_SEPARATOR) +
    kHeaderDefinition + COVOX_MSG_SEPARATOR +
    "MSG: geometry_msgs/Transform\n"
    "Vector3 translation\n"
    "Quaternion rotation\n" COVOX_MSG_SEPARATOR +
    kVector3Definition + COVOX_MSG_SEPARATOR + kQuaternionDefinition;

const std::string kPointStampedDefinition = std::string(
                                                "Header header\n"
                                                "Point point\n" COVOX_MSG_SEPARATOR) +
                                            kHeaderDefinition + COVOX_MSG_SEPARATOR +
                                            kPointDefinition;

const std::string kOdometryDefinition =
    std::string(
        "Header header\n"
        "string child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n" COVOX_MSG_SEPARATOR) +
    kHeaderDefinition + COVOX_MSG_SEPARATOR +
    "MSG: geometry_msgs/PoseWithCovariance\n"
    "Pose pose\n"
    "float64[36] covariance\n" COVOX_MSG_SEPARATOR
    "MSG: geometry_msgs/Pose\n"
    "Point position\n"
    "Quaternion orientation\n" COVOX_MSG_SEPARATOR +
    kPointDefinition + COVOX_MSG_SEPARATOR + kQuaternionDefinition + COVOX_MSG_SEPARATOR +
    "MSG: geometry_msgs/TwistWithCovariance\n"
    "Twist twist\n"
    "float64[36] covariance\n" COVOX_MSG_SEPARATOR
    "MSG: geometry_msgs/Twist\n"
    "Vector3 linear\n"
    "Vector3 angular\n" COVOX_MSG_SEPARATOR +
    kVector3Definition;

#undef COVOX_MSG_SEPARATOR

void write_header(ByteWriter& out, const Header& header) {
  out.u32(header.seq);
  out.time(header.stamp);
  out.string(header.frame_id);
}

Header read_header(ByteReader& in) {
  Header header;
  header.seq = in.u32("header.seq");
  header.stamp = in.time("header.stamp");
  header.frame_id = in.string("header.frame_id");
  return header;
}

void write_vector3(ByteWriter& out, const Eigen::Vector3d& value) {
  out.f64(value.x());
  out.f64(value.y());
  out.f64(value.z());
}

Eigen::Vector3d read_vector3(ByteReader& in, const char* field) {
  Eigen::Vector3d value;
  for (int i = 0; i < 3; ++i) value[i] = in.f64(field);
  return value;
}

// geometry_msgs/Transform and geometry_msgs/Pose have the same layout: a vector of three float64
// and a quaternion x, y, z, w.
void write_rigid(ByteWriter& out, const Eigen::Isometry3d& pose) {
  write_vector3(out, pose.translation());
  const Eigen::Quaterniond rotation(pose.linear());
  out.f64(rotation.x());
  out.f64(rotation.y());
  out.f64(rotation.z());
  out.f64(rotation.w());
}

Eigen::Isometry3d read_rigid(ByteReader& in, const char* field) {
  const Eigen::Vector3d translation = read_vector3(in, field);
  double q[4];
  for (double& value : q) value = in.f64(field);
  const Eigen::Quaterniond rotation(q[3], q[0], q[1], q[2]);
  const double norm = rotation.norm();
  if (!translation.allFinite() || !std::isfinite(norm) || std::abs(norm - 1.0) > 1e-3) {
    throw Error(in.what() + ": " + field + " is not a rigid transform (quaternion norm " +
                std::to_string(norm) +
                ", translation finite: " + (translation.allFinite() ? "yes" : "no") + ")");
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rotation.normalized().toRotationMatrix();
  pose.translation() = translation;
  return pose;
}

void expect_consumed(const ByteReader& in, const char* type) {
  if (in.remaining() != 0) {
    throw Error(in.what() + ": " + std::to_string(in.remaining()) + " bytes left over after a " +
                type + " (a message of another type?)");
  }
}

}  // namespace

const MessageType& point_cloud2_type() {
  static const MessageType type{"sensor_msgs/PointCloud2", "1158d486dd51d683ce2f1be655c3c181",
                                kPointCloud2Definition.c_str()};
  return type;
}

const MessageType& tf_message_type() {
  static const MessageType type{"tf2_msgs/TFMessage", "94810edda583a504dfda3829e70d7eec",
                                kTfMessageDefinition.c_str()};
  return type;
}

const MessageType& point_stamped_type() {
  static const MessageType type{"geometry_msgs/PointStamped", "c63aecb41bfdfd6b7e1fac37c7cbe7bf",
                                kPointStampedDefinition.c_str()};
  return type;
}

const MessageType& odometry_type() {
  static const MessageType type{"nav_msgs/Odometry", "cd5e73d190d741a2f92e81eda573aca7",
                                kOdometryDefinition.c_str()};
  return type;
}

std::vector<uint8_t> serialize(const PointCloud2Message& message) {
  std::vector<uint8_t> bytes;
  bytes.reserve(message.data.size() + 256);
  ByteWriter out(&bytes);
  write_header(out, message.header);
  out.u32(message.height);
  out.u32(message.width);
  out.u32(static_cast<uint32_t>(message.fields.size()));
  for (const PointField& field : message.fields) {
    out.string(field.name);
    out.u32(field.offset);
    out.u8(field.datatype);
    out.u32(field.count);
  }
  out.u8(message.is_bigendian ? 1 : 0);
  out.u32(message.point_step);
  out.u32(message.row_step);
  out.u32(static_cast<uint32_t>(message.data.size()));
  out.bytes(message.data.data(), message.data.size());
  out.u8(message.is_dense ? 1 : 0);
  return bytes;
}

std::vector<uint8_t> serialize(const TfMessage& message) {
  std::vector<uint8_t> bytes;
  ByteWriter out(&bytes);
  out.u32(static_cast<uint32_t>(message.transforms.size()));
  for (const TransformStamped& transform : message.transforms) {
    write_header(out, transform.header);
    out.string(transform.child_frame_id);
    write_rigid(out, transform.T_parent_child);
  }
  return bytes;
}

std::vector<uint8_t> serialize(const PointStampedMessage& message) {
  std::vector<uint8_t> bytes;
  ByteWriter out(&bytes);
  write_header(out, message.header);
  write_vector3(out, message.point);
  return bytes;
}

std::vector<uint8_t> serialize(const OdometryMessage& message) {
  std::vector<uint8_t> bytes;
  ByteWriter out(&bytes);
  write_header(out, message.header);
  out.string(message.child_frame_id);
  write_rigid(out, message.T_parent_child);
  for (double value : message.pose_covariance) out.f64(value);
  write_vector3(out, message.linear_velocity);
  write_vector3(out, message.angular_velocity);
  for (double value : message.twist_covariance) out.f64(value);
  return bytes;
}

PointCloud2Message parse_point_cloud2(const uint8_t* data, size_t size, const std::string& what) {
  ByteReader in(data, size, what);
  PointCloud2Message message;
  message.header = read_header(in);
  message.height = in.u32("height");
  message.width = in.u32("width");
  const uint32_t field_count = in.u32("fields");
  // Each field takes at least 13 bytes: a count beyond that is corruption, not a huge cloud.
  if (field_count > in.remaining() / 13)
    throw Error(what + ": implausible PointCloud2 field count " + std::to_string(field_count));
  message.fields.resize(field_count);
  for (PointField& field : message.fields) {
    field.name = in.string("fields.name");
    field.offset = in.u32("fields.offset");
    field.datatype = in.u8("fields.datatype");
    field.count = in.u32("fields.count");
  }
  message.is_bigendian = in.u8("is_bigendian") != 0;
  message.point_step = in.u32("point_step");
  message.row_step = in.u32("row_step");
  const uint32_t data_size = in.u32("data");
  const uint8_t* first = in.bytes(data_size, "data");
  message.data.assign(first, first + data_size);
  message.is_dense = in.u8("is_dense") != 0;
  expect_consumed(in, "sensor_msgs/PointCloud2");
  return message;
}

TfMessage parse_tf_message(const uint8_t* data, size_t size, const std::string& what) {
  ByteReader in(data, size, what);
  TfMessage message;
  const uint32_t count = in.u32("transforms");
  // A transform takes at least 76 bytes.
  if (count > in.remaining() / 76)
    throw Error(what + ": implausible TFMessage transform count " + std::to_string(count));
  message.transforms.resize(count);
  for (TransformStamped& transform : message.transforms) {
    transform.header = read_header(in);
    transform.child_frame_id = in.string("child_frame_id");
    transform.T_parent_child = read_rigid(in, "transform");
  }
  expect_consumed(in, "tf2_msgs/TFMessage");
  return message;
}

PointStampedMessage parse_point_stamped(const uint8_t* data, size_t size, const std::string& what) {
  ByteReader in(data, size, what);
  PointStampedMessage message;
  message.header = read_header(in);
  message.point = read_vector3(in, "point");
  expect_consumed(in, "geometry_msgs/PointStamped");
  return message;
}

OdometryMessage parse_odometry(const uint8_t* data, size_t size, const std::string& what) {
  ByteReader in(data, size, what);
  OdometryMessage message;
  message.header = read_header(in);
  message.child_frame_id = in.string("child_frame_id");
  message.T_parent_child = read_rigid(in, "pose.pose");
  for (double& value : message.pose_covariance) value = in.f64("pose.covariance");
  message.linear_velocity = read_vector3(in, "twist.twist.linear");
  message.angular_velocity = read_vector3(in, "twist.twist.angular");
  for (double& value : message.twist_covariance) value = in.f64("twist.covariance");
  expect_consumed(in, "nav_msgs/Odometry");
  return message;
}

PointCloud2Message make_point_cloud2(const Header& header,
                                     const std::vector<Eigen::Vector3f>& points_m,
                                     const std::vector<float>& intensities) {
  const bool with_intensity = !intensities.empty();
  if (with_intensity && intensities.size() != points_m.size()) {
    throw Error("make_point_cloud2: " + std::to_string(intensities.size()) + " intensities for " +
                std::to_string(points_m.size()) + " points");
  }
  PointCloud2Message cloud;
  cloud.header = header;
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(points_m.size());
  cloud.fields = {{"x", 0, kFloat32, 1}, {"y", 4, kFloat32, 1}, {"z", 8, kFloat32, 1}};
  if (with_intensity) cloud.fields.push_back({"intensity", 12, kFloat32, 1});
  cloud.point_step = with_intensity ? 16 : 12;
  cloud.row_step = cloud.point_step * cloud.width;
  cloud.data.resize(static_cast<size_t>(cloud.row_step));
  uint8_t* out = cloud.data.data();
  for (size_t i = 0; i < points_m.size(); ++i, out += cloud.point_step) {
    std::memcpy(out, points_m[i].data(), 12);
    if (with_intensity) std::memcpy(out + 12, &intensities[i], 4);
  }
  cloud.is_dense = true;
  return cloud;
}

namespace {

// The fields extract_points reads, checked against the cloud's layout.
struct ExtractedFields {
  const PointField* xyz[3] = {nullptr, nullptr, nullptr};
  const PointField* intensity = nullptr;  // null: none, or of no numeric type
  PointTimeReader times;
};

void check_cloud_sizes(const PointCloud2Message& cloud, const std::string& what,
                       std::initializer_list<const PointField*> fields) {
  for (const PointField* field : fields) {
    if (field == nullptr) continue;
    const uint64_t end = uint64_t(field->offset) + point_field_type_size(field->datatype);
    if (end > cloud.point_step) {
      throw Error(what + ": PointCloud2 field '" + field->name + "' ends at byte " +
                  std::to_string(end) + " but point_step is " + std::to_string(cloud.point_step));
    }
  }
  if (uint64_t(cloud.width) * cloud.point_step > cloud.row_step) {
    throw Error(what + ": PointCloud2 row_step " + std::to_string(cloud.row_step) +
                " is less than width " + std::to_string(cloud.width) + " x point_step " +
                std::to_string(cloud.point_step));
  }
  if (uint64_t(cloud.height) * cloud.row_step > cloud.data.size()) {
    throw Error(what + ": PointCloud2 data has " + std::to_string(cloud.data.size()) +
                " bytes, height " + std::to_string(cloud.height) + " x row_step " +
                std::to_string(cloud.row_step) + " needed");
  }
}

ExtractedFields find_extracted_fields(const PointCloud2Message& cloud, const std::string& what,
                                      double column_sweep_duration_s) {
  if (cloud.is_bigendian) throw Error(what + ": big-endian PointCloud2 data is not supported");
  ExtractedFields fields;
  const PointField* time_field = nullptr;
  fields.times =
      make_point_time_reader(cloud.fields, cloud.width, cloud.height, column_sweep_duration_s);
  for (const PointField& field : cloud.fields) {
    for (int axis = 0; axis < 3; ++axis) {
      if (field.name == std::string(1, "xyz"[axis])) fields.xyz[axis] = &field;
    }
    if (field.name == "intensity" && point_field_type_size(field.datatype) != 0)
      fields.intensity = &field;
    if (!fields.times.field_name().empty() && field.name == fields.times.field_name())
      time_field = &field;
  }
  for (int axis = 0; axis < 3; ++axis) {
    const PointField* field = fields.xyz[axis];
    if (field == nullptr) throw Error(what + ": PointCloud2 has no " + "xyz"[axis] + " field");
    if (field->datatype != kFloat32 && field->datatype != kFloat64) {
      throw Error(what + ": PointCloud2 field '" + field->name +
                  "' is not float32 or float64 (datatype " + std::to_string(field->datatype) + ")");
    }
  }
  check_cloud_sizes(cloud, what,
                    {fields.xyz[0], fields.xyz[1], fields.xyz[2], fields.intensity, time_field});
  return fields;
}

}  // namespace

PointCloud extract_points(const PointCloud2Message& cloud, const std::string& what,
                          ReadStats* stats, double column_sweep_duration_s) {
  const ExtractedFields fields = find_extracted_fields(cloud, what, column_sweep_duration_s);
  PointCloud points;
  const size_t count = size_t(cloud.width) * cloud.height;
  points.points_m.reserve(count);
  if (fields.intensity != nullptr) points.intensities.reserve(count);
  if (fields.times.has_times()) points.times_s.reserve(count);
  size_t dropped = 0;
  for (uint32_t row = 0; row < cloud.height; ++row) {
    const uint8_t* point = cloud.data.data() + size_t(row) * cloud.row_step;
    for (uint32_t column = 0; column < cloud.width; ++column, point += cloud.point_step) {
      Eigen::Vector3f p;
      for (int axis = 0; axis < 3; ++axis) {
        p[axis] = static_cast<float>(
            read_point_field_element(point + fields.xyz[axis]->offset, fields.xyz[axis]->datatype));
      }
      if (!p.allFinite()) {
        ++dropped;
        continue;
      }
      points.points_m.push_back(p);
      if (fields.times.has_times()) points.times_s.push_back(fields.times.time_s(point, column));
      if (fields.intensity != nullptr) {
        points.intensities.push_back(static_cast<float>(read_point_field_element(
            point + fields.intensity->offset, fields.intensity->datatype)));
      }
    }
  }
  if (stats != nullptr) stats->dropped_non_finite_points += dropped;
  return points;
}

}  // namespace rosbag
}  // namespace io
}  // namespace covox

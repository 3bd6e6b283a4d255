#include "sim/sim_flight_bag.h"

#include <cmath>
#include <cstring>
#include <string>
#include <utility>

#include "covoxslam/core/error.h"

namespace covox {
namespace sim {

namespace rb = io::rosbag;

Eigen::Isometry3d T_imu_os1_sensor() {
  // The LiDAR sits 8 cm above and 3 cm ahead of the IMU, axes aligned.
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(0.03, 0.0, 0.08);
  return T;
}

Eigen::Isometry3d T_os1_sensor_os1_lidar() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

std::vector<Eigen::Vector3f> to_os1_lidar(const std::vector<Vec3f>& points_sensor_m) {
  // p_lidar = T_sensor_lidar^-1 p_sensor: the 180 degree yaw negates x and y.
  const Eigen::Isometry3f T_lidar_sensor = T_os1_sensor_os1_lidar().inverse().cast<float>();
  std::vector<Eigen::Vector3f> points_lidar_m(points_sensor_m.size());
  for (size_t i = 0; i < points_sensor_m.size(); ++i) {
    points_lidar_m[i] = T_lidar_sensor * Eigen::Vector3f(points_sensor_m[i].x, points_sensor_m[i].y,
                                                         points_sensor_m[i].z);
  }
  return points_lidar_m;
}

void append_uint32_field(rb::PointCloud2Message* cloud, const std::string& name,
                         const std::vector<uint32_t>& values) {
  const size_t count = size_t(cloud->width) * cloud->height;
  if (values.size() != count) {
    throw Error("flight bag: " + std::to_string(values.size()) + " values of field '" + name +
                "' for " + std::to_string(count) + " points");
  }
  const uint32_t old_step = cloud->point_step, new_step = old_step + 4;
  std::vector<uint8_t> data(count * new_step);
  for (size_t i = 0; i < count; ++i) {
    std::memcpy(&data[i * new_step], &cloud->data[i * old_step], old_step);
    std::memcpy(&data[i * new_step + old_step], &values[i], 4);  // little-endian, as the cloud
  }
  cloud->fields.push_back({name, old_step, io::kUint32, 1});
  cloud->point_step = new_step;
  cloud->row_step = new_step * cloud->width;
  cloud->data = std::move(data);
}

FlightBagWriter::FlightBagWriter(const std::string& path, const ArcheBagLayout& layout)
    : layout_(layout), bag_(path) {
  tf_static_connection_ =
      bag_.add_connection("/tf_static", rb::tf_message_type(), /*latching=*/true);
  tf_connection_ = bag_.add_connection("/tf", rb::tf_message_type());
  cloud_connection_ = bag_.add_connection(layout_.cloud_topic, rb::point_cloud2_type());
  truth_connection_ = bag_.add_connection(layout_.ground_truth_topic, rb::point_stamped_type());
}

void FlightBagWriter::write_scan(double stamp_s, const Eigen::Isometry3d& truth,
                                 const Eigen::Isometry3d& odometry,
                                 const std::vector<Vec3f>& points_sensor_m,
                                 const std::vector<float>& intensities) {
  write_odometry(stamp_s, odometry);
  write_cloud(stamp_s, stamp_s, truth, points_sensor_m, {}, intensities);
}

rb::TfMessage static_tf_message(const ArcheBagLayout& layout, const rb::RosTime& stamp) {
  rb::TfMessage statics;
  rb::TransformStamped lever;
  lever.header.stamp = stamp;
  lever.header.frame_id = layout.imu_frame;
  lever.child_frame_id = layout.sensor_frame;
  lever.T_parent_child = T_imu_os1_sensor();
  rb::TransformStamped yaw = lever;
  yaw.header.frame_id = layout.sensor_frame;
  yaw.child_frame_id = layout.lidar_frame;
  yaw.T_parent_child = T_os1_sensor_os1_lidar();
  statics.transforms = {lever, yaw};
  return statics;
}

rb::TfMessage odometry_tf_message(const ArcheBagLayout& layout, double stamp_s,
                                  const Eigen::Isometry3d& odometry, uint32_t sequence) {
  rb::TfMessage tf;
  rb::TransformStamped odom;
  odom.header.seq = sequence;
  odom.header.stamp = rb::RosTime::from_seconds(stamp_s);
  odom.header.frame_id = layout.odom_frame;
  odom.child_frame_id = layout.imu_frame;
  odom.T_parent_child = odometry * T_imu_os1_sensor().inverse();
  tf.transforms.push_back(odom);
  return tf;
}

double bag_stamp_s(double stamp_s) { return rb::RosTime::from_seconds(stamp_s).to_seconds(); }

void FlightBagWriter::write_static(const rb::RosTime& stamp) {
  // Stamped with the first message: rosbag play publishes it latched before anything else.
  bag_.write(tf_static_connection_, stamp, rb::serialize(static_tf_message(layout_, stamp)));
  static_written_ = true;
}

void FlightBagWriter::write_odometry(double stamp_s, const Eigen::Isometry3d& odometry) {
  const rb::RosTime stamp = rb::RosTime::from_seconds(stamp_s);
  if (!static_written_) write_static(stamp);
  bag_.write(tf_connection_, stamp,
             rb::serialize(odometry_tf_message(layout_, stamp_s, odometry, tf_sequence_++)));
}

void FlightBagWriter::write_cloud(double stamp_s, double recorded_s, const Eigen::Isometry3d& truth,
                                  const std::vector<Vec3f>& points_sensor_m,
                                  const std::vector<uint32_t>& times_ns,
                                  const std::vector<float>& intensities) {
  const rb::RosTime stamp = rb::RosTime::from_seconds(stamp_s);
  const rb::RosTime recorded = rb::RosTime::from_seconds(recorded_s);
  if (recorded < stamp) {
    throw Error("flight bag: a cloud stamped " + std::to_string(stamp_s) +
                " s recorded before it, at " + std::to_string(recorded_s) + " s");
  }
  if (!static_written_) write_static(stamp);
  const std::vector<Eigen::Vector3f> points_lidar_m = to_os1_lidar(points_sensor_m);
  rb::Header cloud_header;
  cloud_header.seq = cloud_sequence_;
  cloud_header.stamp = stamp;
  cloud_header.frame_id = layout_.lidar_frame;
  rb::PointCloud2Message cloud = rb::make_point_cloud2(cloud_header, points_lidar_m, intensities);
  if (!times_ns.empty()) append_uint32_field(&cloud, "t", times_ns);
  bag_.write(cloud_connection_, recorded, rb::serialize(cloud));

  rb::PointStampedMessage fix;
  fix.header.seq = cloud_sequence_;
  fix.header.stamp = stamp;
  fix.header.frame_id = layout_.ground_truth_frame;
  fix.point = truth.translation();
  bag_.write(truth_connection_, recorded, rb::serialize(fix));
  ++cloud_sequence_;
}

}  // namespace sim
}  // namespace covox

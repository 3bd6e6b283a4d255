#include "sim_flight_bag.h"

#include <cmath>

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
  const rb::RosTime stamp = rb::RosTime::from_seconds(stamp_s);
  if (!static_written_) {
    // Stamped with the first scan: rosbag play publishes it latched before anything else.
    rb::TfMessage statics;
    rb::TransformStamped lever;
    lever.header.stamp = stamp;
    lever.header.frame_id = layout_.imu_frame;
    lever.child_frame_id = layout_.sensor_frame;
    lever.T_parent_child = T_imu_os1_sensor();
    rb::TransformStamped yaw = lever;
    yaw.header.frame_id = layout_.sensor_frame;
    yaw.child_frame_id = layout_.lidar_frame;
    yaw.T_parent_child = T_os1_sensor_os1_lidar();
    statics.transforms = {lever, yaw};
    bag_.write(tf_static_connection_, stamp, rb::serialize(statics));
    static_written_ = true;
  }

  rb::TfMessage tf;
  rb::TransformStamped odom;
  odom.header.seq = sequence_;
  odom.header.stamp = stamp;
  odom.header.frame_id = layout_.odom_frame;
  odom.child_frame_id = layout_.imu_frame;
  odom.T_parent_child = odometry * T_imu_os1_sensor().inverse();
  tf.transforms.push_back(odom);
  bag_.write(tf_connection_, stamp, rb::serialize(tf));

  const std::vector<Eigen::Vector3f> points_lidar_m = to_os1_lidar(points_sensor_m);
  rb::Header cloud_header;
  cloud_header.seq = sequence_;
  cloud_header.stamp = stamp;
  cloud_header.frame_id = layout_.lidar_frame;
  bag_.write(cloud_connection_, stamp,
             rb::serialize(rb::make_point_cloud2(cloud_header, points_lidar_m, intensities)));

  rb::PointStampedMessage fix;
  fix.header.seq = sequence_;
  fix.header.stamp = stamp;
  fix.header.frame_id = layout_.ground_truth_frame;
  fix.point = truth.translation();
  bag_.write(truth_connection_, stamp, rb::serialize(fix));
  ++sequence_;
}

}  // namespace sim
}  // namespace covox

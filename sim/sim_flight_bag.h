#pragma once
// A simulated flight as a ROS bag with the ARCHE topic layout (that of the ARCHE flights voxgraph
// was evaluated on), so that the offline runner, `rosbag play` + the nodelet (launch/arche.launch)
// and any tool made for the real flights take it unchanged: the layout (ArcheBagLayout), the
// static extrinsics of the simulated OS1-64, and the writer (docs/design.md, "Tools, modules and
// tests").
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/vec3.h"
#include "covoxslam/io/rosbag_writer.h"
#include "sim/sim_flight.h"

namespace covox {
namespace sim {

// The topics and frames of the bag:
//   cloud_topic         sensor_msgs/PointCloud2, frame os1_lidar, float32 x y z and, for a
//                       distorted scan, the Ouster driver's uint32 field t (nanoseconds after the
//                       scan's start, the cloud's stamp)
//   /tf                 odom -> imu from the drifting odometry, at the odometry rate (100 Hz by
//                       default, as a VIO's output) and at every scan stamp
//   /tf_static          (latched) imu -> os1_sensor (a small lever arm) and os1_sensor ->
//                       os1_lidar (180 degree yaw, as the real OS1-64)
//   ground_truth_topic  geometry_msgs/PointStamped, ground-truth position of the LiDAR origin in
//                       frame "enu" (the simulated RTK fix has no lever arm and no noise)
// The simulator's sensor frame is os1_sensor (x forward, z up); its poses are T_world_os1_sensor.
struct ArcheBagLayout {
  std::string cloud_topic = "/penguin/os1_cloud_node/points";
  std::string ground_truth_topic = "/penguin/piksi_node/enu_pose_fix";
  std::string odom_frame = "odom";
  std::string imu_frame = "imu";
  std::string sensor_frame = "os1_sensor";
  std::string lidar_frame = "os1_lidar";
  std::string ground_truth_frame = "enu";
};

// The static extrinsics the bag carries.
Eigen::Isometry3d T_imu_os1_sensor();
Eigen::Isometry3d T_os1_sensor_os1_lidar();

// Points of the os1_sensor frame in the os1_lidar frame, in single precision: what the bag's
// clouds hold, bit for bit.
std::vector<Eigen::Vector3f> to_os1_lidar(const std::vector<Vec3f>& points_sensor_m);

// The /tf_static message (imu -> os1_sensor -> os1_lidar) stamped `stamp`, and the /tf message
// odom -> imu at `stamp_s` from `odometry` (T_odom_os1_sensor): what the writer records.
io::rosbag::TfMessage static_tf_message(const ArcheBagLayout& layout,
                                        const io::rosbag::RosTime& stamp);
io::rosbag::TfMessage odometry_tf_message(const ArcheBagLayout& layout, double stamp_s,
                                          const Eigen::Isometry3d& odometry, uint32_t sequence);

// `stamp_s` as the bag stores a stamp (whole nanoseconds) and a reader gets it back in seconds.
double bag_stamp_s(double stamp_s);

// `cloud` with one more field, a uint32 `name` after its others, holding `values` (one per point
// of a dense cloud).
void append_uint32_field(io::rosbag::PointCloud2Message* cloud, const std::string& name,
                         const std::vector<uint32_t>& values);

// The tf for a scan is written before the scan, at the same stamp, so a lookup at the cloud stamp
// never needs to extrapolate. A cloud can be recorded when its sweep ends (as the driver
// publishes it, one sweep after its stamp), after the tf samples up to that time: a lookup at any
// point time of the sweep then interpolates between samples already in the bag (SimulatedMission's
// scans are written so, sim_mission_bag.h).
class FlightBagWriter {
 public:
  // Writes the static transforms; throws covox::Error when the bag cannot be created.
  FlightBagWriter(const std::string& path, const ArcheBagLayout& layout = ArcheBagLayout());
  // One instantaneous scan: tf odom -> imu from `odometry` (T_odom_os1_sensor), the cloud (points
  // in the os1_sensor frame, rotated into os1_lidar here), intensities (one per point, or empty),
  // and the ground-truth fix from `truth` (T_world_os1_sensor), all at `stamp_s`.
  void write_scan(double stamp_s, const Eigen::Isometry3d& truth, const Eigen::Isometry3d& odometry,
                  const std::vector<Vec3f>& points_sensor_m, const std::vector<float>& intensities);
  // tf odom -> imu at `stamp_s` from `odometry` (T_odom_os1_sensor).
  void write_odometry(double stamp_s, const Eigen::Isometry3d& odometry);
  // The cloud stamped `stamp_s` and the fix from `truth` (T_world_os1_sensor) at that stamp, both
  // recorded at `recorded_s` (>= stamp_s): points as in write_scan, with the field t from
  // `times_ns` (one per point; empty: no field) and intensities (one per point, or empty).
  void write_cloud(double stamp_s, double recorded_s, const Eigen::Isometry3d& truth,
                   const std::vector<Vec3f>& points_sensor_m, const std::vector<uint32_t>& times_ns,
                   const std::vector<float>& intensities);
  void close() { bag_.close(); }
  uint64_t message_count() const { return bag_.message_count(); }

 private:
  // The static transforms, once, stamped `stamp`.
  void write_static(const io::rosbag::RosTime& stamp);
  ArcheBagLayout layout_;
  io::rosbag::BagWriter bag_;
  uint32_t cloud_connection_ = 0, tf_connection_ = 0, tf_static_connection_ = 0,
           truth_connection_ = 0;
  bool static_written_ = false;
  uint32_t cloud_sequence_ = 0, tf_sequence_ = 0;
};

}  // namespace sim
}  // namespace covox

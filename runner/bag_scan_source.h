#pragma once
// Scans from a ROS bag: sensor_msgs/PointCloud2 on one topic, each with the odometry pose of the
// cloud's frame at the cloud's stamp, looked up in the bag's tf tree (/tf and /tf_static) from
// `odom_frame`, or from nav_msgs/Odometry messages on `odometry_topic` (then the odometry's child
// frame is connected to the cloud frame through /tf_static). The reference trajectory is read
// from geometry_msgs/PointStamped (position-only, like ARCHE's RTK fixes) or nav_msgs/Odometry
// messages on `reference_topic`, whichever type the topic has. BagScanSource says how it reads.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "covoxslam/io/rosbag_reader.h"
#include "covoxslam/io/rosbag_tf_buffer.h"
#include "runner/scan_source.h"

namespace covox {
namespace tools {

struct BagScanOptions {
  std::string cloud_topic = "/penguin/os1_cloud_node/points";
  std::string odom_frame = "odom";
  std::string odometry_topic;                                        // empty: odometry from tf
  std::string reference_topic = "/penguin/piksi_node/enu_pose_fix";  // empty or absent: none
  // The cloud's frame; empty: the frame_id each cloud carries.
  std::string sensor_frame;
  // Points nearer than this are the drone's own frame and propellers (ARCHE's launch crops them).
  double min_range_m = 0.0;
  // Organised clouds without a time field: their columns are taken as fired over this long
  // (deskew.sweep_duration_s; io/point_times.h).
  double column_sweep_duration_s = 0.1;
  // The sensor's extrinsic, the nodelet's ros.base_frame and ros.T_base_sensor (points of the
  // cloud's frame into base_frame); unset: tf from odom_frame to the cloud's frame. Set (see
  // bag_extrinsic.h), the cloud's pose is tf odom_frame -> base_frame times the extrinsic, so a
  // bag without the static transform from the robot to its LiDAR maps as one with it; where the
  // bag has that transform too, the extrinsic wins, and the first scan's log line gives both.
  std::string base_frame = "base_link";
  std::optional<Eigen::Isometry3d> T_base_sensor;
  std::string extrinsic_origin;  // where T_base_sensor came from, for the log ("--extrinsic")
};

// The poses on `topic`: geometry_msgs/PointStamped (position-only) or nav_msgs/Odometry, stamped
// with their headers; repeated or out-of-order stamps and non-finite positions are left out.
// Throws covox::Error for a missing topic or another type, listing the bag's topics.
io::Trajectory read_bag_trajectory(io::rosbag::BagReader& bag, const std::string& topic);

// The tf and the reference are read first, in one pass (they are small); then the clouds are read
// one by one in time order. A cloud whose pose cannot be looked up (tf does not reach its stamp or
// frame) or whose fields cannot be read is skipped and counted. A cloud with per-point times (a
// `t` or `time` field, or organised) gets them and the odometry at its first and last point time,
// for de-skewing; where tf does not reach those times the scan goes without (the pipeline counts
// it).
class BagScanSource : public ScanSource {
 public:
  // Throws covox::Error for an unreadable bag, a cloud topic that is missing or not a
  // PointCloud2, or an odometry/reference topic of an unsupported type.
  BagScanSource(const std::string& path, const BagScanOptions& options);
  size_t size() const override { return clouds_.size(); }
  bool next(SourceScan* scan) override;
  std::string describe() const override;
  double duration_s() const override;
  // The configuration's deskew.sweep_duration_s, for the clouds read from now on.
  void set_column_sweep_duration_s(double seconds) { options_.column_sweep_duration_s = seconds; }

 private:
  // Reads /tf, /tf_static, the odometry topic and the reference in one pass over the bag.
  void read_poses();
  // T_odom_sensor of a cloud in `frame` at `stamp_s`, from tf alone or through the extrinsic;
  // false with the reason when tf cannot give it.
  bool lookup_sensor_pose(const std::string& frame, double stamp_s,
                          Eigen::Isometry3d* T_odom_sensor, std::string* reason);

  std::string path_;
  BagScanOptions options_;
  io::rosbag::BagReader bag_;
  io::rosbag::TfBuffer tf_;
  std::vector<io::rosbag::IndexEntry> clouds_;
  size_t next_cloud_ = 0;
  // The points nearer than min_range_m left out, with their times.
  void keep_points(const io::PointCloud& points, SourceScan* scan) const;
  int64_t dropped_non_finite_points_ = 0;
  bool extrinsic_logged_ = false;
};

}  // namespace tools
}  // namespace covox

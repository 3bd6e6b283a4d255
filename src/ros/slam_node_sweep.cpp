// SlamNode de-skewing input: the odometry at a timed cloud's first and last point time, so that
// the SLAM system can move every point to the cloud's stamp (pipeline/scan_deskew.h). The sweep's
// end lies after the stamp on drivers that stamp the sweep's start (Ouster), so a cloud may wait
// for the odometry to reach it, as it waits for its own pose.
#include <algorithm>
#include <string>

#include <tf2_eigen/tf2_eigen.h>

#include "covoxslam/ros/slam_node.h"

namespace covox {
namespace ros_layer {

SlamNode::PoseResult SlamNode::odometry_at_locked(const ros::Time& stamp,
                                                  Eigen::Isometry3d* T_odom_base) {
  if (options_.use_tf_for_odometry) {
    std::string error;
    if (tf_buffer_.canTransform(options_.odom_frame, options_.base_frame, stamp, &error)) {
      *T_odom_base = tf2::transformToEigen(
          tf_buffer_.lookupTransform(options_.odom_frame, options_.base_frame, stamp));
      return PoseResult::kReady;
    }
    // Before the newest sample the buffer would have answered: what is missing is in the past.
    return error.find("past") != std::string::npos ? PoseResult::kDrop : PoseResult::kWait;
  }
  const pipeline::PoseLookup lookup = odometry_buffer_.lookup(stamp.toSec(), T_odom_base);
  switch (pipeline::decide_pending(lookup, 0.0, 1.0)) {
    case pipeline::PendingDecision::kUse:
      return PoseResult::kReady;
    case pipeline::PendingDecision::kWait:
      return PoseResult::kWait;
    default:
      return PoseResult::kDrop;
  }
}

SlamNode::PoseResult SlamNode::sweep_odometry_locked(const PendingScan& scan,
                                                     const Eigen::Isometry3d& T_odom_sensor,
                                                     pipeline::SweepOdometry* sweep) {
  *sweep = pipeline::SweepOdometry();
  if (scan.times_s.empty() || !slam_->config().deskew.enabled) return PoseResult::kReady;
  const auto [earliest, latest] = std::minmax_element(scan.times_s.begin(), scan.times_s.end());
  sweep->begin_s = *earliest;
  sweep->end_s = *latest;
  Eigen::Isometry3d T_odom_base_stamp, T_odom_base_begin, T_odom_base_end;
  const PoseResult at_stamp = odometry_at_locked(scan.stamp, &T_odom_base_stamp);
  const PoseResult at_begin =
      odometry_at_locked(scan.stamp + ros::Duration(sweep->begin_s), &T_odom_base_begin);
  const PoseResult at_end =
      odometry_at_locked(scan.stamp + ros::Duration(sweep->end_s), &T_odom_base_end);
  const bool ready = at_stamp == PoseResult::kReady && at_begin == PoseResult::kReady &&
                     at_end == PoseResult::kReady;
  if (!ready) {
    const bool may_come = at_stamp != PoseResult::kDrop && at_begin != PoseResult::kDrop &&
                          at_end != PoseResult::kDrop;
    const double waited_s = (ros::WallTime::now() - scan.received).toSec();
    // Without the sweep's odometry the cloud is mapped as it is (counted by the SLAM system).
    return may_come && waited_s <= options_.tf_wait_timeout_s ? PoseResult::kWait
                                                              : PoseResult::kReady;
  }
  // The extrinsic at the stamp carries over to the sweep's ends (it is rigid).
  const Eigen::Isometry3d T_base_sensor = T_odom_base_stamp.inverse() * T_odom_sensor;
  sweep->T_odom_sensor_begin = T_odom_base_begin * T_base_sensor;
  sweep->T_odom_sensor_end = T_odom_base_end * T_base_sensor;
  sweep->known = true;
  return PoseResult::kReady;
}

}  // namespace ros_layer
}  // namespace covox

// SlamNode input: clouds and depth images become scans, wait for their pose (tf or odometry
// topic) and go to the SLAM system; loop closures go straight to it.
#include <tf2_eigen/tf2_eigen.h>

#include "covoxslam/io/depth_image_points.h"
#include "covoxslam/io/pointcloud_fields.h"
#include "covoxslam/ros/message_conversions.h"
#include "covoxslam/ros/slam_node.h"

namespace covox {
namespace ros_layer {

void SlamNode::count_drop(pipeline::DropCounter& counter, const std::string& what) {
  if (counter.count(ros::WallTime::now().toSec())) {
    ROS_WARN_STREAM("covoxslam: " << what << " (" << counter.logged_batch()
                                  << " such drops since the last message, " << counter.total()
                                  << " in total)");
  }
}

void SlamNode::cloud_callback(const sensor_msgs::PointCloud2::ConstPtr& cloud) {
  io::CloudDecodeOptions decode_options;
  decode_options.use_color = options_.use_color;
  decode_options.use_intensity = options_.use_intensity;
  decode_options.intensity_max_value = static_cast<float>(options_.intensity_max_value);
  io::DecodedCloud decoded;
  const io::CloudDecodeResult result = io::decode_point_cloud(
      point_cloud_layout(*cloud), cloud->data.data(), cloud->data.size(), decode_options, &decoded);
  std::lock_guard<std::mutex> lock(input_mutex_);
  ++clouds_received_;
  if (!result.ok()) {
    if (drops_.bad_layout.count(ros::WallTime::now().toSec())) {
      ROS_ERROR_STREAM("covoxslam: dropped the PointCloud2 in frame '"
                       << cloud->header.frame_id << "' at " << cloud->header.stamp << ": "
                       << result.message << " (" << drops_.bad_layout.logged_batch()
                       << " such drops since the last message, " << drops_.bad_layout.total()
                       << " in total)");
    }
    return;
  }
  if (decoded.points_m.empty()) {
    count_drop(drops_.empty_cloud,
               "dropped a cloud at " + std::to_string(cloud->header.stamp.toSec()) +
                   " s with no finite point (" + std::to_string(decoded.dropped_non_finite) +
                   " non-finite of " + std::to_string(decoded.points_in) + ")");
    return;
  }
  if (cloud->header.frame_id.empty()) {
    count_drop(drops_.unknown_frame, "dropped a cloud with an empty frame_id");
    return;
  }
  PendingScan scan;
  scan.stamp = cloud->header.stamp;
  scan.frame = cloud->header.frame_id;
  if (scan.frame.front() == '/') scan.frame.erase(0, 1);  // tf2 frame ids have no leading slash
  scan.points_m = std::move(decoded.points_m);
  scan.colors = std::move(decoded.colors);
  scan.received = ros::WallTime::now();
  enqueue_locked(std::move(scan));
}

void SlamNode::depth_callback(const sensor_msgs::Image::ConstPtr& depth,
                              const sensor_msgs::CameraInfo::ConstPtr& info) {
  depth_color_callback(depth, info, nullptr);
}

void SlamNode::depth_color_callback(const sensor_msgs::Image::ConstPtr& depth,
                                    const sensor_msgs::CameraInfo::ConstPtr& info,
                                    const sensor_msgs::Image::ConstPtr& color) {
  const io::ImageLayout depth_layout = image_layout(*depth);
  io::ImageLayout color_layout;
  if (color) color_layout = image_layout(*color);
  io::DepthToPointsOptions unproject;
  unproject.pixel_stride = options_.depth_pixel_stride;
  unproject.max_depth_m = static_cast<float>(options_.depth_max_m);
  io::DepthPoints points;
  const std::string problem = io::depth_image_to_points(
      depth_layout, depth->data.data(), depth->data.size(), camera_intrinsics(*info),
      color ? &color_layout : nullptr, color ? color->data.data() : nullptr,
      color ? color->data.size() : 0, unproject, &points);
  std::lock_guard<std::mutex> lock(input_mutex_);
  ++clouds_received_;
  if (!problem.empty()) {
    count_drop(drops_.bad_image, "dropped a depth image at " +
                                     std::to_string(depth->header.stamp.toSec()) +
                                     " s: " + problem);
    return;
  }
  if (points.points_m.empty()) {
    count_drop(drops_.empty_cloud, "dropped a depth image without a valid pixel");
    return;
  }
  PendingScan scan;
  scan.stamp = depth->header.stamp;
  scan.frame = depth->header.frame_id;
  if (!scan.frame.empty() && scan.frame.front() == '/') scan.frame.erase(0, 1);
  scan.points_m = std::move(points.points_m);
  scan.colors = std::move(points.colors);
  scan.received = ros::WallTime::now();
  enqueue_locked(std::move(scan));
}

void SlamNode::enqueue_locked(PendingScan scan) {
  if (static_cast<int>(pending_.size()) >= options_.max_pending_clouds) {
    const double stamp_s = pending_.front().stamp.toSec();
    pending_.pop_front();
    count_drop(drops_.pending_overflow, "more than max_pending_clouds (" +
                                            std::to_string(options_.max_pending_clouds) +
                                            ") clouds wait for tf: dropped the oldest, at " +
                                            std::to_string(stamp_s) + " s");
  }
  pending_.push_back(std::move(scan));
  process_pending_locked();
}

void SlamNode::odometry_callback(const nav_msgs::Odometry::ConstPtr& odometry) {
  const geometry_msgs::Pose& pose = odometry->pose.pose;
  geometry_msgs::Transform transform;
  transform.translation.x = pose.position.x;
  transform.translation.y = pose.position.y;
  transform.translation.z = pose.position.z;
  transform.rotation = pose.orientation;
  const Eigen::Isometry3d T_odom_base = to_isometry(transform);
  std::lock_guard<std::mutex> lock(input_mutex_);
  if (!odometry_buffer_.add(odometry->header.stamp.toSec(), T_odom_base)) {
    count_drop(drops_.bad_odometry,
               "ignored an odometry message at " + std::to_string(odometry->header.stamp.toSec()) +
                   " s: its stamp is not after the previous one or its pose is not a finite "
                   "rigid transform");
    return;
  }
  process_pending_locked();
}

SlamNode::PoseResult SlamNode::sensor_pose_locked(const PendingScan& scan,
                                                  Eigen::Isometry3d* T_odom_sensor) {
  const double waited_s = (ros::WallTime::now() - scan.received).toSec();
  const double timeout_s = options_.tf_wait_timeout_s;
  const std::string at = " at " + std::to_string(scan.stamp.toSec()) + " s";

  // Odometry: T_odom_base.
  Eigen::Isometry3d T_odom_base = Eigen::Isometry3d::Identity();
  if (options_.use_tf_for_odometry) {
    std::string error;
    if (tf_buffer_.canTransform(options_.odom_frame, options_.base_frame, scan.stamp, &error)) {
      T_odom_base = tf2::transformToEigen(
          tf_buffer_.lookupTransform(options_.odom_frame, options_.base_frame, scan.stamp));
    } else if (waited_s <= timeout_s) {
      return PoseResult::kWait;
    } else {
      const bool unknown = !tf_buffer_._frameExists(options_.odom_frame) ||
                           !tf_buffer_._frameExists(options_.base_frame);
      count_drop(unknown ? drops_.unknown_frame : drops_.tf_timeout,
                 "dropped the cloud" + at + ": no tf " + options_.odom_frame + " -> " +
                     options_.base_frame + " within tf_wait_timeout_s = " +
                     std::to_string(timeout_s) + " s (" + error + ")");
      return PoseResult::kDrop;
    }
  } else {
    const pipeline::PoseLookup lookup = odometry_buffer_.lookup(scan.stamp.toSec(), &T_odom_base);
    switch (pipeline::decide_pending(lookup, waited_s, timeout_s)) {
      case pipeline::PendingDecision::kUse:
        break;
      case pipeline::PendingDecision::kWait:
        return PoseResult::kWait;
      case pipeline::PendingDecision::kDropTimedOut:
        count_drop(drops_.tf_timeout, "dropped the cloud" + at +
                                          ": no odometry covering it within tf_wait_timeout_s (" +
                                          pipeline::to_string(lookup) + ")");
        return PoseResult::kDrop;
      case pipeline::PendingDecision::kDropNever:
        count_drop(drops_.pose_unavailable,
                   "dropped the cloud" + at + ": its odometry is " + pipeline::to_string(lookup));
        return PoseResult::kDrop;
    }
  }

  // Extrinsic: T_base_sensor.
  Eigen::Isometry3d T_base_sensor = options_.T_base_sensor;
  if (options_.use_tf_for_extrinsic && scan.frame != options_.base_frame) {
    std::string error;
    if (tf_buffer_.canTransform(options_.base_frame, scan.frame, scan.stamp, &error)) {
      T_base_sensor = tf2::transformToEigen(
          tf_buffer_.lookupTransform(options_.base_frame, scan.frame, scan.stamp));
    } else if (waited_s <= timeout_s) {
      return PoseResult::kWait;
    } else {
      const bool unknown = !tf_buffer_._frameExists(scan.frame);
      count_drop(unknown ? drops_.unknown_frame : drops_.tf_timeout,
                 "dropped the cloud" + at + " in frame '" + scan.frame + "': " +
                     (unknown ? std::string("the frame is not in tf")
                              : "no tf " + options_.base_frame + " -> " + scan.frame) +
                     " within tf_wait_timeout_s = " + std::to_string(timeout_s) + " s (" + error +
                     ")");
      return PoseResult::kDrop;
    }
  }
  *T_odom_sensor = T_odom_base * T_base_sensor;
  return PoseResult::kReady;
}

void SlamNode::process_pending_locked() {
  // In arrival order: the SLAM system needs increasing stamps, so a scan never overtakes an
  // older one that still waits.
  while (!pending_.empty()) {
    PendingScan& scan = pending_.front();
    Eigen::Isometry3d T_odom_sensor;
    const PoseResult result = sensor_pose_locked(scan, &T_odom_sensor);
    if (result == PoseResult::kWait) return;
    if (result == PoseResult::kReady) {
      pipeline::Scan input;
      input.stamp_s = scan.stamp.toSec();
      input.T_odom_sensor = T_odom_sensor;
      input.points_sensor_m = std::move(scan.points_m);
      input.colors = std::move(scan.colors);
      if (slam_->add_scan(std::move(input))) {
        ++scans_added_;
        last_added_stamp_ = scan.stamp;
      } else {
        count_drop(drops_.rejected_by_slam, "the SLAM system refused the cloud at " +
                                                std::to_string(scan.stamp.toSec()) +
                                                " s (see its counters in ~diagnostics)");
      }
    }
    pending_.pop_front();
  }
}

void SlamNode::loop_closure_callback(const covoxslam::LoopClosure::ConstPtr& closure) {
  pipeline::LoopClosure input;
  input.from_stamp_s = closure->from_timestamp.toSec();
  input.to_stamp_s = closure->to_timestamp.toSec();
  input.T_from_to = to_isometry(closure->transform);
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) input.information(r, c) = closure->information[6 * r + c];
  }
  // The SLAM system checks it, counts a refusal and says why in the log.
  if (!slam_->add_loop_closure(input)) {
    std::lock_guard<std::mutex> lock(input_mutex_);
    count_drop(drops_.loop_closures_rejected,
               "a loop closure was refused (see the log line above)");
  }
}

}  // namespace ros_layer
}  // namespace covox

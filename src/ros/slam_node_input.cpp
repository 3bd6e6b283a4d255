// SlamNode input: clouds and depth images become scans, wait for their pose (tf or odometry
// topic) and go to the SLAM system; loop closures go straight to it. Time going backwards is
// detected here (accept_time_locked).
#include <tf2_eigen/tf2_eigen.h>

#include <sstream>

#include "covoxslam/io/depth_image_points.h"
#include "covoxslam/io/pointcloud_fields.h"
#include "covoxslam/ros/message_conversions.h"
#include "covoxslam/ros/slam_node.h"

namespace covox {
namespace ros_layer {

namespace {

// tf cannot answer `stamp` now and never will: its buffer starts after it (tf keeps data in time
// order, so older data does not arrive later), or the stamp lies further back than the buffer
// keeps at all.
bool tf_never_answers(const std::string& error, const ros::Time& stamp,
                      const ros::Duration& cache_length) {
  if (error.find("extrapolation into the past") != std::string::npos) return true;
  const ros::Time now = ros::Time::now();
  return !now.isZero() && now > stamp && (now - stamp) > cache_length;
}

std::string seconds_text(double seconds) {
  std::ostringstream text;
  text.precision(3);
  text << std::fixed << seconds;
  return text.str();
}

}  // namespace

void SlamNode::count_drop(pipeline::DropCounter& counter, const std::string& what) {
  last_refusal_ = what;
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
  decode_options.read_point_times = slam_->config().deskew.enabled;
  decode_options.column_sweep_duration_s = slam_->config().deskew.sweep_duration_s;
  io::DecodedCloud decoded;
  const io::CloudDecodeResult result = io::decode_point_cloud(
      point_cloud_layout(*cloud), cloud->data.data(), cloud->data.size(), decode_options, &decoded);
  std::lock_guard<std::mutex> lock(input_mutex_);
  ++clouds_received_;
  if (!result.ok()) {
    last_refusal_ = "a PointCloud2 with a bad layout: " + result.message;
    if (drops_.bad_layout.count(ros::WallTime::now().toSec())) {
      ROS_ERROR_STREAM("covoxslam: dropped the PointCloud2 in frame '"
                       << cloud->header.frame_id << "' at " << cloud->header.stamp << ": "
                       << result.message << " (" << drops_.bad_layout.logged_batch()
                       << " such drops since the last message, " << drops_.bad_layout.total()
                       << " in total)");
    }
    return;
  }
  points_dropped_non_finite_ += decoded.dropped_non_finite;
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
  if (!accept_time_locked(cloud->header.stamp, &cloud_time_, "cloud")) {
    count_drop(drops_.refused_after_time_jump, "refused the cloud at " +
                                                   seconds_text(cloud->header.stamp.toSec()) +
                                                   " s: " + refusing_reason_);
    return;
  }
  PendingScan scan;
  scan.stamp = cloud->header.stamp;
  scan.frame = cloud->header.frame_id;
  if (scan.frame.front() == '/') scan.frame.erase(0, 1);  // tf2 frame ids have no leading slash
  scan.points_m = std::move(decoded.points_m);
  scan.colors = std::move(decoded.colors);
  scan.times_s = std::move(decoded.point_times_s);
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
  if (!accept_time_locked(depth->header.stamp, &cloud_time_, "depth image")) {
    count_drop(drops_.refused_after_time_jump, "refused the depth image at " +
                                                   seconds_text(depth->header.stamp.toSec()) +
                                                   " s: " + refusing_reason_);
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
  // While clouds are refused after a time jump, their odometry is of no use either.
  if (!accept_time_locked(odometry->header.stamp, &odometry_time_, "odometry")) return;
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
    } else if (tf_never_answers(error, scan.stamp, tf_buffer_.getCacheLength())) {
      count_drop(drops_.pose_unavailable, "dropped the cloud" + at + ": tf " + options_.odom_frame +
                                              " -> " + options_.base_frame +
                                              " holds no data that old (" + error + ")");
      return PoseResult::kDrop;
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
    } else if (tf_never_answers(error, scan.stamp, tf_buffer_.getCacheLength())) {
      count_drop(drops_.pose_unavailable, "dropped the cloud" + at + ": tf " + options_.base_frame +
                                              " -> " + scan.frame + " holds no data that old (" +
                                              error + ")");
      return PoseResult::kDrop;
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
  // finish_map has stopped the SLAM system for a moment: the clouds wait for it to run again.
  if (finishing_) return;
  // In arrival order: the SLAM system needs increasing stamps, so a scan never overtakes an
  // older one that still waits.
  while (!pending_.empty()) {
    PendingScan& scan = pending_.front();
    Eigen::Isometry3d T_odom_sensor;
    const PoseResult result = sensor_pose_locked(scan, &T_odom_sensor);
    if (result == PoseResult::kWait) return;
    pipeline::SweepOdometry sweep;
    if (result == PoseResult::kReady &&
        sweep_odometry_locked(scan, T_odom_sensor, &sweep) == PoseResult::kWait) {
      return;
    }
    if (result == PoseResult::kReady) {
      pipeline::Scan input;
      input.stamp_s = scan.stamp.toSec();
      input.T_odom_sensor = T_odom_sensor;
      input.points_sensor_m = std::move(scan.points_m);
      input.colors = std::move(scan.colors);
      input.point_times_s = std::move(scan.times_s);
      input.sweep = sweep;
      if (slam_->add_scan(std::move(input))) {
        ++scans_added_;
        last_added_stamp_ = scan.stamp;
      } else {
        count_drop(drops_.rejected_by_slam, "the SLAM system refused the cloud at " +
                                                seconds_text(scan.stamp.toSec()) +
                                                " s: " + slam_refusal_reason());
      }
    }
    pending_.pop_front();
  }
}

std::string SlamNode::slam_refusal_reason() {
  const pipeline::SlamCounters now = slam_->counters();
  const pipeline::SlamCounters& before = refusal_reference_;
  const struct {
    bool grew;
    const char* why;
  } reasons[] = {
      {now.scans_dropped_bad_stamp > before.scans_dropped_bad_stamp,
       "its stamp is not after the previous cloud's (a repeated stamp, or time going back by "
       "less than time_jump_min_s)"},
      {now.scans_dropped_invalid_pose > before.scans_dropped_invalid_pose,
       "its pose is not a finite rigid transform"},
      {now.scans_dropped_empty_cloud > before.scans_dropped_empty_cloud, "it has no points"},
      {now.scans_dropped_bad_colors > before.scans_dropped_bad_colors,
       "its colour count does not match its point count"},
      {now.scans_dropped_bad_point_times > before.scans_dropped_bad_point_times,
       "its point times are not finite or do not match its points"},
      {now.scans_rejected_not_running > before.scans_rejected_not_running,
       "the SLAM system is not running"}};
  refusal_reference_ = now;
  for (const auto& reason : reasons) {
    if (reason.grew) return reason.why;
  }
  return "see the SLAM counters in ~diagnostics";
}

void SlamNode::clear_input_locked() {
  pending_.clear();
  odometry_buffer_.clear();
  last_clock_ = ros::Time();
  cloud_time_ = TimeLine();
  odometry_time_ = TimeLine();
  last_added_stamp_ = ros::Time();
  refusing_reason_.clear();
}

void SlamNode::check_clock_locked() {
  // Only simulated time is watched: a wall clock stepped back (NTP) is no new time line.
  if (!ros::Time::isSimTime()) return;
  const ros::Time now = ros::Time::now();
  if (now.isZero()) return;  // before the first /clock message
  if (!last_clock_.isZero() && now < last_clock_)
    on_time_jump_locked("the ROS clock", last_clock_.toSec(), now.toSec());
  last_clock_ = now;
}

bool SlamNode::accept_time_locked(const ros::Time& stamp, TimeLine* line, const char* input) {
  check_clock_locked();
  if (!line->newest.isZero() && !stamp.isZero() &&
      (line->newest - stamp).toSec() > options_.time_jump_min_s) {
    if (++line->backwards_in_a_row >= 2) {
      on_time_jump_locked(std::string("the ") + input + " stamps", line->newest.toSec(),
                          stamp.toSec());
    }
  } else {
    line->backwards_in_a_row = 0;
  }
  if (!refusing_reason_.empty()) return false;
  if (stamp > line->newest) line->newest = stamp;
  return true;
}

void SlamNode::on_time_jump_locked(const std::string& cause, double from_s, double to_s) {
  // The clock and each input's stamps report the same jump one after the other: within
  // time_jump_min_s of wall time after a handled jump, only the references start again.
  const ros::WallTime now_wall = ros::WallTime::now();
  const bool same_jump =
      !last_jump_wall_.isZero() && (now_wall - last_jump_wall_).toSec() < options_.time_jump_min_s;
  last_jump_wall_ = now_wall;
  cloud_time_ = TimeLine();
  odometry_time_ = TimeLine();
  if (same_jump) return;
  ++time_jumps_;
  const std::string jump = "time went backwards by " + seconds_text(from_s - to_s) + " s (" +
                           cause + " jumped from " + seconds_text(from_s) + " s to " +
                           seconds_text(to_s) + " s: a bag played again or looped?)";
  if (options_.time_jump_policy == "refuse") {
    // Nothing mapped from now on fits the map's time line: refuse until reset or load_map.
    pending_.clear();
    odometry_buffer_.clear();
    refusing_reason_ =
        jump + "; clouds are refused until ~reset or ~load_map (time_jump_policy: refuse)";
    ROS_WARN_STREAM("covoxslam: " << refusing_reason_);
    return;
  }
  ROS_WARN_STREAM(
      "covoxslam: " << jump << "; the map is reset and mapping starts again with the next cloud "
                    << "(time_jump_policy: reset)");
  clear_input_locked();
  slam_->reset();
  slam_->resume();
  ++automatic_resets_;
  markers_reset_requested_ = true;
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

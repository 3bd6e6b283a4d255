// SlamNode output: the mission -> odom correction and the submap frames on tf (tf thread), the
// corrected path, submap poses, meshes (per submap, sent once when new or re-meshed), bounding
// boxes, the pose graph, ESDF slices and diagnostics (visualisation thread; the services publish
// the map through publish_map() too).
#include <covoxslam/SubmapPoses.h>
#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/Path.h>

#include "covoxslam/map/mesh_colors.h"
#include "covoxslam/ros/message_conversions.h"
#include "covoxslam/ros/slam_node.h"

namespace covox {
namespace ros_layer {

namespace {

std::string submap_frame(int64_t id) { return "submap_" + std::to_string(id); }

// Submap meshes: the namespace of their markers (id = submap id).
constexpr const char* kMeshNamespace = "submap_mesh";

geometry_msgs::TransformStamped frame_transform(const std::string& parent, int64_t id,
                                                const Eigen::Isometry3d& T_parent_submap) {
  geometry_msgs::TransformStamped frame;
  frame.header.frame_id = parent;
  frame.child_frame_id = submap_frame(id);
  frame.transform = to_transform_msg(T_parent_submap);
  return frame;
}

bool same_pose(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  // 1 mm / about 0.06 degrees: below what rviz shows, above solver noise.
  return (a.translation() - b.translation()).norm() < 1e-3 &&
         (a.linear() - b.linear()).cwiseAbs().maxCoeff() < 1e-3;
}

diagnostic_msgs::KeyValue entry(const std::string& key, const std::string& value) {
  diagnostic_msgs::KeyValue pair;
  pair.key = key;
  pair.value = value;
  return pair;
}

void add_timing(diagnostic_msgs::DiagnosticStatus* status, const std::string& name,
                const pipeline::ModuleTiming& t) {
  status->values.push_back(entry(name + "_calls", std::to_string(t.calls)));
  status->values.push_back(entry(name + "_mean_ms", std::to_string(t.mean_ms())));
  status->values.push_back(entry(name + "_max_ms", std::to_string(1000.0 * t.max_s)));
}

void add_slam_counters(diagnostic_msgs::DiagnosticStatus* status,
                       const pipeline::SlamCounters& counters, int64_t sensor_queue_length,
                       int64_t submap_queue_length) {
  const pipeline::PlaceRecognitionCounts& recognition = counters.place_recognition;
  const struct {
    const char* key;
    int64_t value;
  } values[] = {
      {"sensor_queue_length", sensor_queue_length},
      {"submap_queue_length", submap_queue_length},
      {"scans_integrated", counters.scans_integrated},
      {"scans_dropped_total", counters.scans_dropped_total()},
      {"scans_dropped_queue_full", counters.scans_dropped_queue_full},
      {"scans_dropped_invalid_pose", counters.scans_dropped_invalid_pose},
      {"scans_dropped_bad_stamp", counters.scans_dropped_bad_stamp},
      {"scans_rejected_not_running", counters.scans_rejected_not_running},
      {"scans_discarded_at_reset", counters.scans_discarded_at_reset},
      {"scans_failed", counters.scans_failed},
      {"points_integrated", counters.points_integrated},
      {"points_dropped_by_integrator", counters.points_dropped_by_integrator},
      {"scans_deskewed", counters.scans_deskewed},
      {"scans_not_deskewed_no_times_moving", counters.scans_not_deskewed_no_times_moving},
      {"scans_not_deskewed_no_sweep_odometry", counters.scans_not_deskewed_no_sweep_odometry},
      {"scans_dropped_bad_point_times", counters.scans_dropped_bad_point_times},
      {"submaps_created", counters.submaps_created},
      {"submaps_finished", counters.submaps_finished},
      {"submaps_dropped_queue_full", counters.submaps_dropped_queue_full},
      {"submaps_failed", counters.submaps_failed},
      {"submaps_loaded", counters.submaps_loaded},
      {"submaps_resident", counters.memory.submaps_resident},
      {"submaps_compact", counters.memory.submaps_compact},
      {"submaps_on_disk", counters.memory.submaps_on_disk},
      {"submap_resident_bytes", counters.memory.resident_bytes},
      {"submap_compact_bytes", counters.memory.compact_bytes},
      {"submap_disk_bytes", counters.memory.disk_bytes},
      {"submap_mesh_bytes", counters.memory.mesh_bytes},
      {"submap_restores", counters.memory.restores},
      {"submap_spill_failures", counters.memory.spill_failures},
      {"odometry_constraints", counters.odometry_constraints},
      {"registration_attempted", counters.registration.attempted},
      {"registration_accepted", counters.registration.accepted},
      {"registration_rejected_misfit", counters.registration.rejected_misfit},
      {"registration_rejected_by_odometry", counters.registration.rejected_by_odometry},
      {"place_recognition_candidates", recognition.candidates},
      {"place_recognition_verified", recognition.verified},
      {"place_recognition_accepted", recognition.accepted},
      {"place_recognition_rejected_descriptor", recognition.rejected_descriptor},
      {"place_recognition_rejected_overlap", recognition.rejected_overlap},
      {"place_recognition_rejected_registration",
       recognition.verified - recognition.registration.accepted},
      {"place_recognition_unconfirmed", recognition.unconfirmed},
      {"loop_closures_received", counters.loop_closures.received},
      {"loop_closures_added", counters.loop_closures.added},
      {"optimizations", counters.optimizations},
      {"optimizations_failed", counters.optimizations_failed},
      {"optimizations_over_budget", counters.optimizations_over_budget},
      {"resets", counters.resets}};
  for (const auto& value : values)
    status->values.push_back(entry(value.key, std::to_string(value.value)));
  // The submaps' shift from their odometry poses: how far the backend moved the trajectory.
  status->values.push_back(entry("correction_rms_m", std::to_string(counters.correction_rms_m)));
  status->values.push_back(entry("correction_max_m", std::to_string(counters.correction_max_m)));
}

}  // namespace

void SlamNode::publish_tf(const ros::WallTimerEvent&) {
  // tf listeners reject (and warn about) a repeated stamp: with simulated time the clock stands
  // still before and after a bag, so publish only when it moved (backwards too: a bag played
  // again restarts the clock).
  const ros::Time now = ros::Time::now();
  if (now.isZero() || now == last_tf_stamp_) return;
  last_tf_stamp_ = now;
  geometry_msgs::TransformStamped transform;
  transform.header.stamp = now;
  transform.header.frame_id = options_.mission_frame;
  transform.child_frame_id = options_.odom_frame;
  transform.transform = to_transform_msg(slam_->T_world_odom());
  tf_broadcaster_.sendTransform(transform);
}

void SlamNode::rebroadcast_submap_frames(const ros::WallTimerEvent&) {
  std::lock_guard<std::mutex> lock(frames_mutex_);
  std::vector<geometry_msgs::TransformStamped> frames;
  for (const auto& frame : submap_frames_)
    frames.push_back(frame_transform(options_.mission_frame, frame.first, frame.second));
  send_submap_frames_locked(std::move(frames));
}

void SlamNode::send_submap_frames_locked(std::vector<geometry_msgs::TransformStamped> frames) {
  const ros::Time now = ros::Time::now();
  if (frames.empty() || now.isZero()) return;
  // Strictly later than the previous send: a listener drops a frame's repeated stamp. While the
  // simulated clock stands still that is a microsecond later; a clock that jumped back (a bag
  // played again) starts over at its time.
  if (now > frames_stamp_ || now + ros::Duration(1.0) < frames_stamp_) {
    frames_stamp_ = now;
  } else {
    frames_stamp_ += ros::Duration(0, 1000);
  }
  for (geometry_msgs::TransformStamped& frame : frames) frame.header.stamp = frames_stamp_;
  tf_broadcaster_.sendTransform(frames);
}

void SlamNode::publish_visualization(const ros::WallTimerEvent&) {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  // The input thread reset the map (time went backwards): the markers show the discarded one.
  if (markers_reset_requested_.exchange(false)) {
    clear_published_markers_locked();
    publish_map_locked(false, true);
    return;
  }
  publish_map_locked(false, false);
}

void SlamNode::clear_published_markers() {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  clear_published_markers_locked();
}

void SlamNode::clear_published_markers_locked() {
  visualization_msgs::Marker clear;
  clear.header.frame_id = options_.mission_frame;
  clear.header.stamp = ros::Time::now();
  clear.action = visualization_msgs::Marker::DELETEALL;
  visualization_msgs::MarkerArray clear_array;
  clear_array.markers.push_back(clear);
  separated_mesh_publisher_.publish(clear_array);
  pose_graph_publisher_.publish(clear_array);
  combined_mesh_publisher_.publish(clear);
  bounding_boxes_publisher_.publish(clear_array);
  // The latched active-submap slice showed the discarded map.
  active_submap_esdf_slice_publisher_.publish(
      slice_cloud({}, options_.mission_frame, clear.header.stamp));
  published_submaps_.clear();
  published_trajectory_size_ = static_cast<size_t>(-1);  // publish the (empty) path again
  map_changed_ = true;
  esdf_pointcloud_stale_ = true;
  // The discarded submaps' frames are no longer sent (listeners forget them after tf's cache).
  std::lock_guard<std::mutex> lock(frames_mutex_);
  submap_frames_.clear();
}

void SlamNode::publish_path(const std::vector<pipeline::StampedPose>& trajectory,
                            const ros::Time& stamp) {
  nav_msgs::Path path;
  path.header.frame_id = options_.mission_frame;
  path.header.stamp = stamp;
  path.poses.reserve(trajectory.size());
  for (const pipeline::StampedPose& pose : trajectory) {
    geometry_msgs::PoseStamped stamped;
    stamped.header.frame_id = options_.mission_frame;
    stamped.header.stamp.fromSec(pose.stamp_s);
    stamped.pose = to_pose_msg(pose.T_world_sensor);
    path.poses.push_back(stamped);
  }
  path_publisher_.publish(path);
  published_trajectory_size_ = trajectory.size();
}

void SlamNode::publish_submap_poses(const std::vector<pipeline::SubmapInfo>& submaps,
                                    const ros::Time& stamp) {
  covoxslam::SubmapPoses poses;
  poses.header.frame_id = options_.mission_frame;
  poses.header.stamp = stamp;
  for (const pipeline::SubmapInfo& submap : submaps) {
    covoxslam::SubmapPose pose;
    pose.id = submap.id;
    pose.pose = to_pose_msg(submap.T_world_submap);
    pose.odometry_pose = to_pose_msg(submap.T_odom_submap);
    pose.start_stamp.fromSec(submap.statistics.start_stamp_s);
    pose.end_stamp.fromSec(submap.statistics.end_stamp_s);
    pose.scans = submap.statistics.scans;
    pose.blocks = submap.statistics.blocks;
    pose.mesh_triangles = submap.mesh_triangles;
    poses.submaps.push_back(pose);
  }
  submap_poses_publisher_.publish(poses);
}

void SlamNode::publish_submap_frames(const std::vector<pipeline::SubmapInfo>& submaps, bool force) {
  std::lock_guard<std::mutex> lock(frames_mutex_);
  std::map<int64_t, Eigen::Isometry3d> current;
  std::vector<geometry_msgs::TransformStamped> changed;
  for (const pipeline::SubmapInfo& submap : submaps) {
    current[submap.id] = submap.T_world_submap;
    auto sent = submap_frames_.find(submap.id);
    if (force || sent == submap_frames_.end() || !same_pose(sent->second, submap.T_world_submap))
      changed.push_back(frame_transform(options_.mission_frame, submap.id, submap.T_world_submap));
  }
  // Only the changed frames now; the tf thread sends all of them every submap_tf_period_s.
  submap_frames_ = std::move(current);
  send_submap_frames_locked(std::move(changed));
}

visualization_msgs::MarkerArray SlamNode::submap_mesh_markers(const std::vector<int64_t>& ids,
                                                              const std::vector<int64_t>& removed) {
  // Stamp zero: rviz places the markers at the latest transform of their frame (the frames move
  // on /tf, and a new frame's first transform may be stamped after the marker was made).
  const ros::Time stamp;

  visualization_msgs::MarkerArray markers;
  const map::HeightColorRange range{static_cast<float>(options_.mesh_height_color_min_m),
                                    static_cast<float>(options_.mesh_height_color_max_m)};
  for (int64_t id : removed) {
    markers.markers.push_back(
        deletion_marker(submap_frame(id), stamp, kMeshNamespace, static_cast<int>(id)));
  }
  for (int64_t id : ids) {
    map::Mesh mesh;
    Eigen::Isometry3d T_world_submap;
    if (!slam_->submap_mesh(id, &mesh, &T_world_submap)) continue;
    // Vertices in the submap's own frame, which tf places: moving the submap moves the marker.
    // Colours are taken at the submap's pose of now. rviz draws a marker with colours unlit, so
    // neither side of a surface shows black: a mesh with fused colours gets them per vertex
    // (black vertices by height), one without gets a height colour per triangle, shaded by its
    // slope alike from both sides (map::shaded_face_colors).
    visualization_msgs::Marker marker =
        map::has_observed_colors(mesh)
            ? mesh_marker(mesh, map::display_colors(mesh, T_world_submap, range),
                          Eigen::Isometry3d::Identity(), submap_frame(id), stamp, kMeshNamespace,
                          static_cast<int>(id))
            : face_colored_mesh_marker(mesh, map::shaded_face_colors(mesh, T_world_submap, range),
                                       submap_frame(id), stamp, kMeshNamespace,
                                       static_cast<int>(id));
    marker.frame_locked = true;
    markers.markers.push_back(std::move(marker));
  }
  return markers;
}

void SlamNode::send_meshes_to_new_subscriber(const ros::SingleSubscriberPublisher& subscriber) {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  if (!options_.publish_separated_mesh || published_submaps_.empty()) return;
  std::vector<int64_t> ids;
  for (const auto& published : published_submaps_) ids.push_back(published.first);
  subscriber.publish(submap_mesh_markers(ids, {}));
}

void SlamNode::publish_map(bool resend_meshes, bool with_combined_mesh) {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  publish_map_locked(resend_meshes, with_combined_mesh);
}

bool SlamNode::compare_with_published(const std::vector<pipeline::SubmapInfo>& submaps,
                                      bool resend_meshes, std::vector<int64_t>* meshed,
                                      std::vector<int64_t>* removed) const {
  // A new or re-meshed submap sends its mesh; a moved one only its frame.
  bool moved = false;
  for (const pipeline::SubmapInfo& submap : submaps) {
    auto it = published_submaps_.find(submap.id);
    if (resend_meshes || it == published_submaps_.end() ||
        it->second.mesh_triangles != submap.mesh_triangles) {
      meshed->push_back(submap.id);
    } else if (!same_pose(it->second.T_world_submap, submap.T_world_submap)) {
      moved = true;
    }
  }
  // Submaps that disappeared (reset, load_map) are deleted from rviz.
  for (const auto& published : published_submaps_) {
    bool present = false;
    for (const pipeline::SubmapInfo& submap : submaps)
      present = present || submap.id == published.first;
    if (!present) removed->push_back(published.first);
  }
  return moved;
}

void SlamNode::publish_map_locked(bool resend_meshes, bool with_combined_mesh) {
  const ros::Time stamp = ros::Time::now();
  const std::vector<pipeline::StampedPose> trajectory = slam_->corrected_trajectory();
  const std::vector<pipeline::SubmapInfo> submaps = slam_->submaps();

  std::vector<int64_t> meshed, removed;
  const bool moved = compare_with_published(submaps, resend_meshes, &meshed, &removed);
  const bool graph_changed = resend_meshes || with_combined_mesh || map_changed_ || moved ||
                             !meshed.empty() || !removed.empty();
  if (graph_changed || trajectory.size() != published_trajectory_size_)
    publish_path(trajectory, stamp);
  esdf_pointcloud_stale_ = esdf_pointcloud_stale_ || graph_changed;
  // Also when a subscriber came after a change it was not computed for.
  publish_esdf_pointcloud_locked(with_combined_mesh, stamp);
  if (!graph_changed) return;
  map_changed_ = false;

  publish_submap_poses(submaps, stamp);
  // The frames go out before the markers drawn in them.
  publish_submap_frames(submaps, resend_meshes);
  if (options_.publish_separated_mesh && (!meshed.empty() || !removed.empty()))
    separated_mesh_publisher_.publish(submap_mesh_markers(meshed, removed));
  for (int64_t id : removed) published_submaps_.erase(id);
  for (const pipeline::SubmapInfo& submap : submaps) {
    published_submaps_[submap.id] = PublishedSubmap{submap.T_world_submap, submap.mesh_triangles};
  }
  publish_map_overview(submaps, with_combined_mesh, stamp);
}

void SlamNode::publish_map_overview(const std::vector<pipeline::SubmapInfo>& submaps,
                                    bool with_combined_mesh, const ros::Time& stamp) {
  // The combined mesh holds every triangle in the world frame, so any moved submap changes it:
  // it is published on request only (finish_map, generate_mesh, reset, load_map), latched.
  if (options_.publish_combined_mesh && with_combined_mesh) {
    const map::Mesh combined = slam_->combined_mesh();
    const map::HeightColorRange range{static_cast<float>(options_.mesh_height_color_min_m),
                                      static_cast<float>(options_.mesh_height_color_max_m)};
    const Eigen::Isometry3d identity = Eigen::Isometry3d::Identity();
    combined_mesh_publisher_.publish(
        mesh_marker(combined, map::display_colors(combined, identity, range), identity,
                    options_.mission_frame, stamp, "combined_mesh", 0));
  }
  bounding_boxes_publisher_.publish(bounding_box_markers(submaps, options_.mission_frame, stamp));
  pose_graph_publisher_.publish(
      pose_graph_markers(submaps, slam_->constraints(), options_.mission_frame, stamp));

  if (options_.publish_esdf_slices) {
    esdf_slice_publisher_.publish(slice_cloud(slam_->esdf_slice_world(options_.esdf_slice_height_m),
                                              options_.mission_frame, stamp));
    int64_t newest_id = -1;
    submap_esdf_slice_publisher_.publish(
        slice_cloud(slam_->esdf_slice_newest_submap(options_.esdf_slice_height_m, &newest_id),
                    options_.mission_frame, stamp));
  }
}

void SlamNode::publish_active_submap_slice(const ros::WallTimerEvent&) {
  // Costs a copy of the active submap and an ESDF of its slab: only for a listener.
  if (active_submap_esdf_slice_publisher_.getNumSubscribers() == 0) return;
  int64_t active_id = -1;
  std::vector<integrators::SlicePoint> slice;
  try {
    slice = slam_->esdf_slice_active_submap(options_.esdf_slice_height_m, &active_id);
  } catch (const std::exception& error) {
    ROS_ERROR_STREAM_THROTTLE(10.0,
                              "covoxslam: the active submap's ESDF slice failed: " << error.what());
    return;
  }
  // Before the first copy (or with no active submap) nothing is published: the latched slice
  // stays the last real one.
  if (active_id < 0) return;
  active_submap_esdf_slice_publisher_.publish(
      slice_cloud(slice, options_.mission_frame, ros::Time::now()));
}

void SlamNode::add_input_diagnostics(diagnostic_msgs::DiagnosticStatus* status, int64_t* node_drops,
                                     std::string* state) {
  std::lock_guard<std::mutex> lock(input_mutex_);
  const struct {
    const char* key;
    const pipeline::DropCounter& counter;
  } drops[] = {{"clouds_dropped_bad_layout", drops_.bad_layout},
               {"clouds_dropped_empty", drops_.empty_cloud},
               {"images_dropped_bad", drops_.bad_image},
               {"clouds_dropped_tf_timeout", drops_.tf_timeout},
               {"clouds_dropped_unknown_frame", drops_.unknown_frame},
               {"clouds_dropped_pose_unavailable", drops_.pose_unavailable},
               {"clouds_dropped_pending_overflow", drops_.pending_overflow},
               {"clouds_refused_by_slam", drops_.rejected_by_slam},
               {"clouds_refused_after_time_jump", drops_.refused_after_time_jump},
               {"odometry_messages_ignored", drops_.bad_odometry},
               {"loop_closures_refused", drops_.loop_closures_rejected}};
  if (!refusing_reason_.empty()) {
    *state = "refusing clouds: " + refusing_reason_;
  } else if (finishing_) {
    *state = "finishing the map (clouds wait)";
  } else {
    *state = scans_added_ > 0 ? "mapping" : "waiting for the first cloud";
  }
  status->values.push_back(entry("state", *state));
  status->values.push_back(entry("last_refusal", last_refusal_.empty() ? "none" : last_refusal_));
  status->values.push_back(entry("clouds_received", std::to_string(clouds_received_)));
  status->values.push_back(entry("scans_added", std::to_string(scans_added_)));
  status->values.push_back(entry("clouds_waiting_for_tf", std::to_string(pending_.size())));
  status->values.push_back(
      entry("points_dropped_non_finite", std::to_string(points_dropped_non_finite_)));
  status->values.push_back(entry("time_jumps_backwards", std::to_string(time_jumps_)));
  status->values.push_back(entry("automatic_resets", std::to_string(automatic_resets_)));
  *node_drops = 0;
  for (const auto& drop : drops) {
    status->values.push_back(entry(drop.key, std::to_string(drop.counter.total())));
    *node_drops += drop.counter.total();
  }
}

void SlamNode::publish_diagnostics(const ros::WallTimerEvent&) {
  diagnostics_updater_->force_update();
}

void SlamNode::fill_diagnostics(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const pipeline::SlamCounters counters = slam_->counters();
  const pipeline::SlamTimings timings = slam_->timings();
  int64_t node_drops = 0;
  std::string state;
  add_input_diagnostics(&status, &node_drops, &state);
  add_slam_counters(&status, counters, static_cast<int64_t>(slam_->sensor_queue_length()),
                    static_cast<int64_t>(slam_->submap_queue_length()));
  add_timing(&status, "tsdf", timings.tsdf);
  add_timing(&status, "esdf", timings.esdf);
  add_timing(&status, "mesh", timings.mesh);
  add_timing(&status, "registration", timings.registration);
  add_timing(&status, "backend", timings.backend);
  add_timing(&status, "sensor_queue_wait", timings.sensor_queue_wait);
  add_timing(&status, "submap_queue_wait", timings.submap_queue_wait);

  // ERROR while clouds are refused, WARN while inputs are being dropped (since the previous
  // report), OK otherwise; the message is the state.
  const int64_t dropped_total =
      node_drops + counters.scans_dropped_total() + counters.submaps_dropped_queue_full;
  if (state.compare(0, 8, "refusing") == 0) {
    status.level = diagnostic_msgs::DiagnosticStatus::ERROR;
    status.message = state;
  } else if (dropped_total > last_dropped_total_) {
    status.level = diagnostic_msgs::DiagnosticStatus::WARN;
    status.message = state + "; " + std::to_string(dropped_total - last_dropped_total_) +
                     " inputs dropped since the last report";
  } else {
    status.level = diagnostic_msgs::DiagnosticStatus::OK;
    status.message = state;
  }
  last_dropped_total_ = dropped_total;
}

}  // namespace ros_layer
}  // namespace covox

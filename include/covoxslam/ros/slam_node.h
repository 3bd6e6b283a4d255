#pragma once
// SlamNode: the ROS face of pipeline::SlamSystem, shared by the nodelet
// (covoxslam/CovoxSlamNodelet) and the node (covoxslam_node). It turns messages into scans, looks
// up their poses, publishes what the SLAM system knows and serves the map services; everything
// that computes lives in the library. Sensor callbacks run on the node handle's own queue, the
// outputs on four queues with a spinner thread each (tf, visualisation, map services, ESDF
// queries), so that nothing waits behind a slower one. `input_mutex_` guards what the input and
// the services touch, `publish_mutex_` the record of what was published, `frames_mutex_` the
// submap frames. docs/design.md ("The ROS layer") and docs/ros.md describe the clouds' wait for
// their pose, time jumps, the map's lifecycle and the meshes in the submaps' frames.
#include <atomic>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <nav_msgs/Odometry.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include "covoxslam/EsdfQuery.h"
#include "covoxslam/FilePath.h"
#include "covoxslam/LoopClosure.h"
#include "covoxslam/io/output_folder.h"
#include "covoxslam/pipeline/drop_counter.h"
#include "covoxslam/pipeline/slam_system.h"
#include "covoxslam/pipeline/stamped_pose_buffer.h"
#include "covoxslam/ros/node_options.h"

namespace covox {
namespace ros_layer {

// Drops the node counts itself (the SLAM system counts its own, see SlamCounters).
struct InputDropCounters {
  pipeline::DropCounter bad_layout;     // PointCloud2 without x/y/z, wrong point step, short data
  pipeline::DropCounter empty_cloud;    // no finite point left
  pipeline::DropCounter bad_image;      // depth/colour image or camera info not usable
  pipeline::DropCounter tf_timeout;     // the pose did not arrive within tf_wait_timeout_s
  pipeline::DropCounter unknown_frame;  // the cloud's frame (or odom/base) is not in tf at all
  pipeline::DropCounter pose_unavailable;  // older than the tf / odometry buffer, or in a gap
  pipeline::DropCounter pending_overflow;  // more than max_pending_clouds waiting
  pipeline::DropCounter rejected_by_slam;  // SlamSystem::add_scan refused it (see its counters)
  pipeline::DropCounter bad_odometry;      // odometry messages not usable (time backwards, NaN)
  pipeline::DropCounter loop_closures_rejected;
  pipeline::DropCounter refused_after_time_jump;  // time_jump_policy refuse: until reset/load
  explicit InputDropCounters(double interval_s)
      : bad_layout(interval_s),
        empty_cloud(interval_s),
        bad_image(interval_s),
        tf_timeout(interval_s),
        unknown_frame(interval_s),
        pose_unavailable(interval_s),
        pending_overflow(interval_s),
        rejected_by_slam(interval_s),
        bad_odometry(interval_s),
        loop_closures_rejected(interval_s),
        refused_after_time_jump(interval_s) {}
};

class SlamNode {
 public:
  // Reads and checks every parameter of `private_node` (throws covox::Error naming a bad one),
  // starts the SLAM system, subscribes, advertises and starts the timers.
  SlamNode(ros::NodeHandle node, ros::NodeHandle private_node);
  ~SlamNode();
  SlamNode(const SlamNode&) = delete;
  SlamNode& operator=(const SlamNode&) = delete;

 private:
  // A cloud (or unprojected depth image) waiting for its pose.
  struct PendingScan {
    ros::Time stamp;
    std::string frame;
    std::vector<Vec3f> points_m;
    std::vector<Rgb8> colors;
    std::vector<float> times_s;  // empty, or one per point (seconds after `stamp`)
    ros::WallTime received;
  };
  enum class PoseResult { kReady, kWait, kDrop };

  // ---- Input (slam_node_input.cpp) ----
  void cloud_callback(const sensor_msgs::PointCloud2::ConstPtr& cloud);
  void depth_callback(const sensor_msgs::Image::ConstPtr& depth,
                      const sensor_msgs::CameraInfo::ConstPtr& info);
  void depth_color_callback(const sensor_msgs::Image::ConstPtr& depth,
                            const sensor_msgs::CameraInfo::ConstPtr& info,
                            const sensor_msgs::Image::ConstPtr& color);
  void odometry_callback(const nav_msgs::Odometry::ConstPtr& odometry);
  void loop_closure_callback(const covoxslam::LoopClosure::ConstPtr& closure);
  void enqueue_locked(PendingScan scan);
  // The stamps of one input (clouds, or the odometry topic) as seen so far.
  struct TimeLine {
    ros::Time newest;            // zero: none yet
    int backwards_in_a_row = 0;  // messages more than time_jump_min_s before `newest`
  };
  // Time going backwards (see the class comment): the clock against the previous call, `stamp`
  // against `line`. One message far in the past is only stale (it is dropped as such); two in a
  // row start a new time line. Resets the map or starts refusing as time_jump_policy says.
  // Returns false when the input must be refused. Needs input_mutex_.
  bool accept_time_locked(const ros::Time& stamp, TimeLine* line, const char* input);
  // The clock part of it alone (the pending timer runs it too, so a jump is seen without input).
  void check_clock_locked();
  void on_time_jump_locked(const std::string& cause, double from_s, double to_s);
  // Forgets the input side's state (pending clouds, odometry, time references, refusal), for a
  // map that starts again. Needs input_mutex_.
  void clear_input_locked();
  // Why the SLAM system refused the latest scan, from its counters.
  std::string slam_refusal_reason();
  // Hands every pending scan whose pose is known to the SLAM system, in order; drops the ones
  // that timed out or can never be answered. Needs input_mutex_.
  void process_pending_locked();
  // T_odom_sensor of `scan`, or why not (the drop is counted and logged here).
  PoseResult sensor_pose_locked(const PendingScan& scan, Eigen::Isometry3d* T_odom_sensor);
  // ---- De-skewing (slam_node_sweep.cpp) ----
  // The odometry T_odom_base at `stamp` from tf or the odometry topic: kReady, kWait (not there
  // yet) or kDrop (it never will be). Neither waits nor counts.
  PoseResult odometry_at_locked(const ros::Time& stamp, Eigen::Isometry3d* T_odom_base);
  // The sensor's odometry at the first and last point time of a timed scan whose pose at its
  // stamp is T_odom_sensor: kWait while the odometry does not reach the sweep's end yet (up to
  // tf_wait_timeout_s); kReady otherwise, with sweep->known false when it cannot be had.
  PoseResult sweep_odometry_locked(const PendingScan& scan, const Eigen::Isometry3d& T_odom_sensor,
                                   pipeline::SweepOdometry* sweep);
  void count_drop(pipeline::DropCounter& counter, const std::string& what);

  // Advertises the outputs and starts the timers and services on the output queue.
  void start_output();

  // ---- Output (slam_node_output.cpp) ----
  // Advertises the outputs of one queue each (slam_node.cpp).
  void start_tf_output();
  void start_diagnostics();
  void start_services();
  // mission -> odom every tf_publish_period_s; every submap frame each submap_tf_period_s.
  void publish_tf(const ros::WallTimerEvent&);
  void rebroadcast_submap_frames(const ros::WallTimerEvent&);
  void publish_visualization(const ros::WallTimerEvent&);
  // Sends the status now (diagnostic_updater publishes on /diagnostics).
  void publish_diagnostics(const ros::WallTimerEvent&);
  // The diagnostic_updater task: the node's and the SLAM system's counters, state and level.
  void fill_diagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);
  // The node's own counters and state (`state` also receives it); `node_drops` their drop total.
  void add_input_diagnostics(diagnostic_msgs::DiagnosticStatus* status, int64_t* node_drops,
                             std::string* state);
  void publish_active_submap_slice(const ros::WallTimerEvent&);
  // Publishes path, submap poses, meshes (new or re-meshed submaps only), submap frames (new or
  // moved ones), boxes, graph and slices. Visualisation thread only.
  // `resend_meshes`: every submap's mesh and frame (generate_mesh); `with_combined_mesh`: also
  // ~combined_mesh (finish_map, generate_mesh, reset, load_map).
  // Both lock publish_mutex_ (services call them too); the _locked forms need it held.
  void publish_map(bool resend_meshes, bool with_combined_mesh);
  void publish_map_locked(bool resend_meshes, bool with_combined_mesh);
  // Against published_submaps_: the submaps whose mesh is to be sent (new, re-meshed, or all
  // with `resend_meshes`) and those gone; returns whether one of the others moved.
  bool compare_with_published(const std::vector<pipeline::SubmapInfo>& submaps, bool resend_meshes,
                              std::vector<int64_t>* meshed, std::vector<int64_t>* removed) const;
  // What publish_map() sends of the whole map once it changed: the combined mesh (when asked
  // for), boxes, pose graph and slices.
  void publish_map_overview(const std::vector<pipeline::SubmapInfo>& submaps,
                            bool with_combined_mesh, const ros::Time& stamp);
  void publish_path(const std::vector<pipeline::StampedPose>& trajectory, const ros::Time& stamp);
  void publish_submap_poses(const std::vector<pipeline::SubmapInfo>& submaps,
                            const ros::Time& stamp);
  // Records every submap's frame (mission_frame -> submap_<id>) and sends the new or moved ones
  // on /tf (all with `force`); frames of submaps no longer in the map are dropped.
  void publish_submap_frames(const std::vector<pipeline::SubmapInfo>& submaps, bool force);
  // Sends `frames` on /tf with one stamp, later than any sent before (listeners ignore a repeated
  // stamp, and the simulated clock may stand still). Needs frames_mutex_.
  void send_submap_frames_locked(std::vector<geometry_msgs::TransformStamped> frames);
  // Markers of the given submaps' meshes (in their own frames) and deletions of `removed`.
  visualization_msgs::MarkerArray submap_mesh_markers(const std::vector<int64_t>& ids,
                                                      const std::vector<int64_t>& removed);
  // A new ~separated_mesh subscriber gets every published submap's mesh.
  void send_meshes_to_new_subscriber(const ros::SingleSubscriberPublisher& subscriber);
  void clear_published_markers();
  void clear_published_markers_locked();

  // ---- Planner outputs (slam_node_planner.cpp) ----
  // ~esdf_pointcloud: when the map changed (or `force`) and someone subscribes; latched.
  void publish_esdf_pointcloud_locked(bool force, const ros::Time& stamp);
  bool query_esdf(covoxslam::EsdfQuery::Request& request, covoxslam::EsdfQuery::Response& response);

  // ---- Services (slam_node_services.cpp) ----
  bool save_map(covoxslam::FilePath::Request& request, covoxslam::FilePath::Response& response);
  bool load_map(covoxslam::FilePath::Request& request, covoxslam::FilePath::Response& response);
  bool save_trajectory(covoxslam::FilePath::Request& request,
                       covoxslam::FilePath::Response& response);
  bool save_mesh(covoxslam::FilePath::Request& request, covoxslam::FilePath::Response& response);
  bool generate_mesh(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);
  bool finish_map(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);
  bool optimize_pose_graph(std_srvs::Trigger::Request& request,
                           std_srvs::Trigger::Response& response);
  bool reset(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);

  ros::NodeHandle node_;
  ros::NodeHandle private_node_;
  // The output queues (see the class comment): visualisation, tf, map services, ESDF queries.
  ros::CallbackQueue output_queue_;
  ros::NodeHandle output_node_;
  ros::CallbackQueue tf_queue_;
  ros::NodeHandle tf_node_;
  ros::CallbackQueue service_queue_;
  ros::NodeHandle service_node_;
  ros::CallbackQueue query_queue_;
  ros::NodeHandle query_node_;
  std::vector<std::unique_ptr<ros::AsyncSpinner>> output_spinners_;

  NodeOptions options_;
  // The only folder the file services read and write (~ros/output_dir), created and opened here
  // (after options_), so a folder that cannot be made stops the node at start-up.
  io::OutputFolder output_folder_{options_.output_dir, "~ros/output_dir"};
  std::unique_ptr<pipeline::SlamSystem> slam_;

  tf2_ros::Buffer tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  tf2_ros::TransformBroadcaster tf_broadcaster_;

  // Input side, guarded by input_mutex_.
  std::mutex input_mutex_;
  std::deque<PendingScan> pending_;
  pipeline::StampedPoseBuffer odometry_buffer_;
  InputDropCounters drops_;
  int64_t clouds_received_ = 0;
  int64_t scans_added_ = 0;
  int64_t points_dropped_non_finite_ = 0;  // NaN/Inf points inside otherwise valid clouds
  int64_t time_jumps_ = 0;
  int64_t automatic_resets_ = 0;
  ros::Time last_added_stamp_;
  // Time references for detecting a jump backwards (zero: none yet).
  ros::Time last_clock_;
  TimeLine cloud_time_;
  TimeLine odometry_time_;
  // When the latest jump was handled: the clock and the stamps see one jump one after the other.
  ros::WallTime last_jump_wall_;
  // Non-empty while clouds are refused after a time jump (time_jump_policy refuse).
  std::string refusing_reason_;
  // Why the latest cloud was refused or dropped, for ~diagnostics.
  std::string last_refusal_;
  // While finish_map runs, clouds wait in pending_ instead of going to the stopped system.
  bool finishing_ = false;
  // The SLAM counters at the previous refusal: the one that grew names the next refusal's reason.
  pipeline::SlamCounters refusal_reference_;
  // An automatic reset on the input thread asks the output thread to clear the markers.
  std::atomic<bool> markers_reset_requested_{false};

  ros::Subscriber cloud_subscriber_;
  ros::Subscriber odometry_subscriber_;
  ros::Subscriber loop_closure_subscriber_;
  using DepthPolicy =
      message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo>;
  using DepthColorPolicy =
      message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                      sensor_msgs::Image>;
  std::unique_ptr<message_filters::Subscriber<sensor_msgs::Image>> depth_subscriber_;
  std::unique_ptr<message_filters::Subscriber<sensor_msgs::CameraInfo>> info_subscriber_;
  std::unique_ptr<message_filters::Subscriber<sensor_msgs::Image>> color_subscriber_;
  std::unique_ptr<message_filters::Synchronizer<DepthPolicy>> depth_sync_;
  std::unique_ptr<message_filters::Synchronizer<DepthColorPolicy>> depth_color_sync_;
  ros::WallTimer pending_timer_;

  // Output side (visualisation thread only).
  ros::Publisher path_publisher_;
  ros::Publisher submap_poses_publisher_;
  ros::Publisher combined_mesh_publisher_;
  ros::Publisher separated_mesh_publisher_;
  ros::Publisher bounding_boxes_publisher_;
  ros::Publisher pose_graph_publisher_;
  ros::Publisher esdf_slice_publisher_;
  ros::Publisher submap_esdf_slice_publisher_;
  ros::Publisher active_submap_esdf_slice_publisher_;
  ros::Publisher esdf_pointcloud_publisher_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_updater_;
  ros::WallTimer tf_timer_;
  ros::WallTimer submap_frames_timer_;
  ros::WallTimer visualization_timer_;
  ros::WallTimer diagnostics_timer_;
  ros::WallTimer active_slice_timer_;
  std::vector<ros::ServiceServer> services_;
  // What was published (guarded by publish_mutex_): per submap its pose and its mesh's size, to
  // send a moved submap's pose and a new or re-meshed submap's mesh only.
  std::mutex publish_mutex_;
  struct PublishedSubmap {
    Eigen::Isometry3d T_world_submap;
    int64_t mesh_triangles;
  };
  std::map<int64_t, PublishedSubmap> published_submaps_;
  size_t published_trajectory_size_ = 0;
  bool map_changed_ = true;
  // The map changed since ~esdf_pointcloud was last published.
  bool esdf_pointcloud_stale_ = true;
  // The submap frames on /tf and the stamp they were last sent with (guarded by frames_mutex_).
  std::mutex frames_mutex_;
  std::map<int64_t, Eigen::Isometry3d> submap_frames_;
  ros::Time frames_stamp_;
  int64_t last_dropped_total_ = 0;
  ros::Time last_tf_stamp_;
};

}  // namespace ros_layer
}  // namespace covox

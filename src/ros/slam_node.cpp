// SlamNode: construction (parameters, SLAM system, subscriptions, publishers, timers, services).
#include "covoxslam/ros/slam_node.h"

#include <algorithm>
#include <set>

#include <covoxslam/SubmapPoses.h>
#include <nav_msgs/Path.h>
#include <visualization_msgs/Marker.h>
#include <visualization_msgs/MarkerArray.h>

#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/pipeline/slam_parameters.h"
#include "covoxslam/ros/ros_parameter_source.h"

namespace covox {
namespace ros_layer {

namespace {

// The library logs through ROS, so its lines reach rosout with the node's name.
void forward_library_log_to_ros() {
  set_log_sink([](LogLevel level, const std::string& line) {
    switch (level) {
      case LogLevel::kDebug:
        ROS_DEBUG_STREAM("covoxslam: " << line);
        break;
      case LogLevel::kInfo:
        ROS_INFO_STREAM("covoxslam: " << line);
        break;
      case LogLevel::kWarning:
        ROS_WARN_STREAM("covoxslam: " << line);
        break;
      case LogLevel::kError:
        ROS_ERROR_STREAM("covoxslam: " << line);
        break;
    }
  });
}

// Private parameters that neither list knows are most likely misspelt: say so once. The SLAM
// parameters' dotted names are nested on the server (registration/gate/...), the node's own sit
// in the `ros` namespace.
void warn_about_unknown_parameters(const ros::NodeHandle& private_node) {
  std::vector<std::string> all;
  if (!ros::param::getParamNames(all)) return;
  std::set<std::string> known;
  for (const std::string& name : pipeline::slam_parameter_names()) {
    known.insert(RosParameterSource::ros_name(name));
  }
  for (const std::string& name : node_option_names()) known.insert("ros/" + name);
  for (const std::string& name : RosParameterSource::file_parameter_names()) known.insert(name);
  const std::string prefix = private_node.getNamespace() + "/";
  for (const std::string& name : all) {
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    if (!known.count(name.substr(prefix.size()))) {
      ROS_WARN_STREAM("covoxslam: unknown parameter '"
                      << name << "' is ignored (misspelt? docs/parameters.md lists them)");
    }
  }
}

// The SLAM configuration from the private parameters; the device is auto unless one is set.
pipeline::SlamConfig read_slam_parameters(const ros::NodeHandle& private_node) {
  pipeline::SlamConfig config;
  config.device = select_device(DeviceRequest::kAuto);
  pipeline::read_slam_config(RosParameterSource(private_node), &config);
  return config;
}

}  // namespace

SlamNode::SlamNode(ros::NodeHandle node, ros::NodeHandle private_node)
    : node_(node),
      private_node_(private_node),
      output_node_(private_node),
      tf_node_(private_node),
      service_node_(private_node),
      query_node_(private_node),
      options_(read_node_options(private_node)),
      tf_buffer_(ros::Duration(std::max(10.0, options_.odometry_buffer_s))),
      odometry_buffer_(pipeline::StampedPoseBufferConfig{options_.odometry_buffer_s,
                                                         options_.odometry_max_gap_s}),
      drops_(options_.drop_log_interval_s) {
  forward_library_log_to_ros();
  warn_about_unknown_parameters(private_node_);
  const pipeline::SlamConfig config = read_slam_parameters(private_node_);
  slam_ = std::make_unique<pipeline::SlamSystem>(config);
  ROS_INFO_STREAM("covoxslam: mapping on "
                  << describe_device(config.device) << ", voxel " << config.map.voxel_size_m
                  << " m, submaps by " << pipeline::to_string(config.submaps.policy) << "; frames "
                  << options_.mission_frame << " -> " << options_.odom_frame << " -> "
                  << options_.base_frame);

  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(tf_buffer_, node_);

  // Input: on the node handle's own queue.
  cloud_subscriber_ = node_.subscribe("pointcloud", 20, &SlamNode::cloud_callback, this);
  if (!options_.use_tf_for_odometry) {
    odometry_subscriber_ = node_.subscribe("odometry", 200, &SlamNode::odometry_callback, this);
  }
  loop_closure_subscriber_ =
      node_.subscribe("loop_closure_input", 100, &SlamNode::loop_closure_callback, this);
  if (options_.use_depth_images) {
    depth_subscriber_ =
        std::make_unique<message_filters::Subscriber<sensor_msgs::Image>>(node_, "depth/image", 5);
    info_subscriber_ = std::make_unique<message_filters::Subscriber<sensor_msgs::CameraInfo>>(
        node_, "depth/camera_info", 5);
    if (options_.use_color_images) {
      color_subscriber_ = std::make_unique<message_filters::Subscriber<sensor_msgs::Image>>(
          node_, "color/image", 5);
      depth_color_sync_ = std::make_unique<message_filters::Synchronizer<DepthColorPolicy>>(
          DepthColorPolicy(10), *depth_subscriber_, *info_subscriber_, *color_subscriber_);
      depth_color_sync_->registerCallback(&SlamNode::depth_color_callback, this);
    } else {
      depth_sync_ = std::make_unique<message_filters::Synchronizer<DepthPolicy>>(
          DepthPolicy(10), *depth_subscriber_, *info_subscriber_);
      depth_sync_->registerCallback(&SlamNode::depth_callback, this);
    }
  }
  // Clouds waiting for tf are retried (and timed out) even when no new cloud arrives.
  // Wall timers: with simulated time (rosbag play --clock) the clock stops when the bag ends,
  // and waiting, publishing and diagnostics must go on.
  pending_timer_ =
      node_.createWallTimer(ros::WallDuration(0.02), [this](const ros::WallTimerEvent&) {
        std::lock_guard<std::mutex> lock(input_mutex_);
        check_clock_locked();
        process_pending_locked();
      });

  start_output();
  start_tf_output();
  start_diagnostics();
  start_services();
  // One thread per output queue (see the class comment).
  for (ros::CallbackQueue* queue : {&tf_queue_, &output_queue_, &service_queue_, &query_queue_}) {
    output_spinners_.push_back(std::make_unique<ros::AsyncSpinner>(1, queue));
    output_spinners_.back()->start();
  }
}

void SlamNode::start_tf_output() {
  // Its own queue and thread: the correction the robot navigates by never waits behind a service
  // call or a slice.
  tf_node_.setCallbackQueue(&tf_queue_);
  if (options_.publish_tf) {
    tf_timer_ = tf_node_.createWallTimer(ros::WallDuration(options_.tf_publish_period_s),
                                         &SlamNode::publish_tf, this);
  }
  submap_frames_timer_ = tf_node_.createWallTimer(ros::WallDuration(options_.submap_tf_period_s),
                                                  &SlamNode::rebroadcast_submap_frames, this);
}

void SlamNode::start_diagnostics() {
  // On /diagnostics, where rqt_robot_monitor and diagnostic_aggregator look; status name
  // "<node>: slam". Sent by the wall timer (the simulated clock may stand still).
  diagnostics_updater_ = std::make_unique<diagnostic_updater::Updater>(
      output_node_, private_node_, private_node_.getNamespace());
  diagnostics_updater_->setHardwareID(describe_device(slam_->config().device));
  diagnostics_updater_->add("slam", this, &SlamNode::fill_diagnostics);
  diagnostics_timer_ = output_node_.createWallTimer(
      ros::WallDuration(options_.diagnostics_period_s), &SlamNode::publish_diagnostics, this);
}

void SlamNode::start_services() {
  // Map services on their own queue; the ESDF query on another, so a planner is not answered
  // after a long save_map.
  service_node_.setCallbackQueue(&service_queue_);
  services_.push_back(service_node_.advertiseService("save_map", &SlamNode::save_map, this));
  services_.push_back(service_node_.advertiseService("load_map", &SlamNode::load_map, this));
  services_.push_back(
      service_node_.advertiseService("save_trajectory", &SlamNode::save_trajectory, this));
  services_.push_back(service_node_.advertiseService("save_mesh", &SlamNode::save_mesh, this));
  services_.push_back(
      service_node_.advertiseService("generate_mesh", &SlamNode::generate_mesh, this));
  services_.push_back(service_node_.advertiseService("finish_map", &SlamNode::finish_map, this));
  services_.push_back(
      service_node_.advertiseService("optimize_pose_graph", &SlamNode::optimize_pose_graph, this));
  services_.push_back(service_node_.advertiseService("reset", &SlamNode::reset, this));
  query_node_.setCallbackQueue(&query_queue_);
  services_.push_back(query_node_.advertiseService("query_esdf", &SlamNode::query_esdf, this));
}

void SlamNode::start_output() {
  // Visualisation publishers and timers on the visualisation queue.
  output_node_.setCallbackQueue(&output_queue_);
  path_publisher_ = output_node_.advertise<nav_msgs::Path>("pose_history", 1, true);
  submap_poses_publisher_ = output_node_.advertise<covoxslam::SubmapPoses>("submap_poses", 1, true);
  combined_mesh_publisher_ =
      output_node_.advertise<visualization_msgs::Marker>("combined_mesh", 1, true);
  // Not latched: each message holds only new or re-meshed submaps, so a new subscriber is sent
  // every submap on connecting instead (on this queue, the output thread).
  separated_mesh_publisher_ = output_node_.advertise<visualization_msgs::MarkerArray>(
      "separated_mesh", 100,
      [this](const ros::SingleSubscriberPublisher& subscriber) {
        send_meshes_to_new_subscriber(subscriber);
      },
      ros::SubscriberStatusCallback());
  bounding_boxes_publisher_ =
      output_node_.advertise<visualization_msgs::MarkerArray>("submap_bounding_boxes", 1, true);
  pose_graph_publisher_ =
      output_node_.advertise<visualization_msgs::MarkerArray>("pose_graph", 1, true);
  esdf_slice_publisher_ = output_node_.advertise<sensor_msgs::PointCloud2>("esdf_slice", 1, true);
  submap_esdf_slice_publisher_ =
      output_node_.advertise<sensor_msgs::PointCloud2>("submap_esdf_slice", 1, true);
  active_submap_esdf_slice_publisher_ =
      output_node_.advertise<sensor_msgs::PointCloud2>("active_submap_esdf_slice", 1, true);
  esdf_pointcloud_publisher_ =
      output_node_.advertise<sensor_msgs::PointCloud2>("esdf_pointcloud", 1, true);
  visualization_timer_ = output_node_.createWallTimer(
      ros::WallDuration(options_.visualization_period_s), &SlamNode::publish_visualization, this);
  if (options_.publish_esdf_slices && options_.active_submap_esdf_slice_period_s > 0.0) {
    active_slice_timer_ =
        output_node_.createWallTimer(ros::WallDuration(options_.active_submap_esdf_slice_period_s),
                                     &SlamNode::publish_active_submap_slice, this);
  }
}

SlamNode::~SlamNode() {
  // Stop the output threads before the SLAM system they read goes away.
  for (auto& spinner : output_spinners_) spinner->stop();
  services_.clear();
  tf_timer_.stop();
  submap_frames_timer_.stop();
  visualization_timer_.stop();
  diagnostics_timer_.stop();
  active_slice_timer_.stop();
  pending_timer_.stop();
  if (slam_) slam_->shutdown();
}

}  // namespace ros_layer
}  // namespace covox

#pragma once
// The nodelet's own parameters (frames, waiting, input decoding, publishing): the `ros` section of
// a configuration file, ~ros/<name> on the parameter server; the SLAM parameters beside it are
// read by pipeline::read_slam_config(). Every one is documented in docs/parameters.md and checked
// at start-up with an error naming it.
#include <string>

#include <Eigen/Geometry>
#include <ros/node_handle.h>

namespace covox {
namespace ros_layer {

struct NodeOptions {
  // Frames (voxgraph's convention: mission -> odom -> base_link -> sensor).
  std::string mission_frame = "mission";
  std::string odom_frame = "odom";
  std::string base_frame = "base_link";
  // Odometry: tf odom_frame -> base_frame, or a nav_msgs/Odometry topic ("odometry").
  bool use_tf_for_odometry = true;
  // Extrinsic: tf base_frame -> the cloud's frame, or the T_base_sensor parameter.
  bool use_tf_for_extrinsic = true;
  Eigen::Isometry3d T_base_sensor = Eigen::Isometry3d::Identity();
  // A cloud waits this long (wall time) for its odometry / tf, then is dropped (counted).
  double tf_wait_timeout_s = 0.5;
  // Clouds waiting for tf at most; beyond, the oldest is dropped (counted).
  int max_pending_clouds = 20;
  // Odometry topic buffer (use_tf_for_odometry false).
  double odometry_buffer_s = 30.0;
  double odometry_max_gap_s = 1.0;
  // Input decoding.
  bool use_color = true;
  bool use_intensity = true;
  double intensity_max_value = 255.0;
  bool use_depth_images = false;
  bool use_color_images = true;
  int depth_pixel_stride = 1;
  double depth_max_m = 10.0;
  // Publishing.
  bool publish_tf = true;
  double tf_publish_period_s = 0.05;
  double visualization_period_s = 1.0;
  double diagnostics_period_s = 1.0;
  bool publish_esdf_slices = true;
  double esdf_slice_height_m = 0.5;
  // ~active_submap_esdf_slice every this many wall seconds (0: off). The active submap's ESDF is
  // computed for it from a copy of its blocks (SlamSystem::esdf_slice_active_submap), so a low
  // rate keeps the cost small; computed only while someone subscribes.
  double active_submap_esdf_slice_period_s = 2.0;
  bool publish_combined_mesh = true;
  bool publish_separated_mesh = true;
  double drop_log_interval_s = 5.0;
  // Time going backwards (the ROS clock, or input stamps by more than time_jump_min_s): "reset"
  // the map and map on, or "refuse" clouds until ~reset / ~load_map.
  std::string time_jump_policy = "reset";
  double time_jump_min_s = 1.0;
  // Mesh vertices without a fused colour are coloured by world height over this range (m).
  double mesh_height_color_min_m = -1.0;
  double mesh_height_color_max_m = 9.0;
  // The folder of the file services (save_map, load_map, save_mesh, save_trajectory): their
  // file_path names a file inside it (io/output_folder.h). Created at start-up.
  std::string output_dir = default_output_dir();

  // $ROS_HOME/covoxslam, or ~/.ros/covoxslam when ROS_HOME is not set.
  static std::string default_output_dir();
  // ~esdf_pointcloud: the finished submaps' voxels with a distance of at most this many metres
  // (obstacles and the free space around them), at most this many points (the smallest
  // distances kept beyond). Computed only while someone subscribes (and latched).
  bool publish_esdf_pointcloud = true;
  double esdf_pointcloud_max_distance_m = 1.0;
  int esdf_pointcloud_max_points = 300000;
  // ~query_esdf refuses a request with more points than this.
  int esdf_query_max_points = 100000;
  // Every submap frame (mission_frame -> submap_<id>) is sent on /tf again this often, so that a
  // late listener gets them; a new or moved frame goes out at once.
  double submap_tf_period_s = 1.0;
};

// Reads every option set under the private node handle's `ros` namespace (defaults for the
// others) and checks them; throws covox::Error naming the first bad parameter.
NodeOptions read_node_options(const ros::NodeHandle& private_node);

// The option names within the `ros` section, so that unknown (misspelt) private parameters can be
// reported.
const std::vector<std::string>& node_option_names();

}  // namespace ros_layer
}  // namespace covox

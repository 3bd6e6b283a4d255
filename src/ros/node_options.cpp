#include "covoxslam/ros/node_options.h"

#include <cmath>
#include <cstdlib>
#include <vector>

#include <ros/console.h>

#include "covoxslam/core/error.h"
#include "covoxslam/io/transform_numbers.h"
#include "covoxslam/ros/ros_parameter_source.h"

namespace covox {
namespace ros_layer {

namespace {

// The options live in the `ros` section of the configuration (~ros/<name>).
[[noreturn]] void bad(const std::string& name, const std::string& problem) {
  throw Error("parameter 'ros." + name + "': " + problem);
}

void read_frame(const RosParameterSource& source, const std::string& name, std::string* frame) {
  std::string value;
  if (!source.get_text(name, &value)) return;
  if (value.empty()) bad(name, "must not be empty");
  if (value.front() == '/') value.erase(0, 1);  // tf2 frame ids have no leading slash
  *frame = value;
}

void read_flag(const RosParameterSource& source, const std::string& name, bool* flag) {
  bool value = false;
  if (source.get_bool(name, &value)) *flag = value;
}

// A number that must be positive (or >= 0 with allow_zero).
void read_amount(const RosParameterSource& source, const std::string& name, double* amount,
                 bool allow_zero = false) {
  double value = 0.0;
  if (!source.get_number(name, &value)) return;
  if (!std::isfinite(value) || value < 0.0 || (!allow_zero && value == 0.0)) {
    bad(name, std::string(allow_zero ? "must be >= 0" : "must be positive") + ", got " +
                  std::to_string(value));
  }
  *amount = value;
}

void read_count(const RosParameterSource& source, const std::string& name, int* count,
                int minimum) {
  int64_t value = 0;
  if (!source.get_integer(name, &value)) return;
  if (value < minimum || value > 1000000) {
    bad(name,
        "must be in [" + std::to_string(minimum) + ", 1000000], got " + std::to_string(value));
  }
  *count = static_cast<int>(value);
}

// [x, y, z, qx, qy, qz, qw] or a row-major 4x4 matrix (voxgraph's T_base_link_sensor).
Eigen::Isometry3d read_transform(const RosParameterSource& source, const std::string& name,
                                 const Eigen::Isometry3d& fallback) {
  std::vector<double> values;
  if (!source.get_number_list(name, &values)) return fallback;
  return io::transform_from_numbers(values, "parameter 'ros." + name + "'");
}

// time_jump_policy, time_jump_min_s and the mesh height colour range.
void read_time_and_mesh_options(const RosParameterSource& source, NodeOptions* options) {
  if (source.get_text("time_jump_policy", &options->time_jump_policy) &&
      options->time_jump_policy != "reset" && options->time_jump_policy != "refuse") {
    bad("time_jump_policy", "must be reset or refuse, got '" + options->time_jump_policy + "'");
  }
  read_amount(source, "time_jump_min_s", &options->time_jump_min_s);
  const struct {
    const char* name;
    double* height_m;
  } heights[] = {{"mesh_height_color_min_m", &options->mesh_height_color_min_m},
                 {"mesh_height_color_max_m", &options->mesh_height_color_max_m}};
  for (const auto& height : heights) {
    double value = 0.0;
    if (!source.get_number(height.name, &value)) continue;
    if (!std::isfinite(value)) bad(height.name, "must be a finite height in metres");
    *height.height_m = value;
  }
  if (!(options->mesh_height_color_max_m > options->mesh_height_color_min_m))
    bad("mesh_height_color_max_m", "must be above mesh_height_color_min_m");
}

// The 3-D ESDF cloud, the ESDF query service and the submap frames' re-broadcast.
void read_planner_options(const RosParameterSource& source, NodeOptions* options) {
  read_flag(source, "publish_esdf_pointcloud", &options->publish_esdf_pointcloud);
  read_amount(source, "esdf_pointcloud_max_distance_m", &options->esdf_pointcloud_max_distance_m);
  read_count(source, "esdf_pointcloud_max_points", &options->esdf_pointcloud_max_points, 1);
  read_count(source, "esdf_query_max_points", &options->esdf_query_max_points, 1);
  read_amount(source, "submap_tf_period_s", &options->submap_tf_period_s);
}

}  // namespace

std::string NodeOptions::default_output_dir() {
  const char* ros_home = std::getenv("ROS_HOME");
  if (ros_home != nullptr && *ros_home != '\0') return std::string(ros_home) + "/covoxslam";
  const char* home = std::getenv("HOME");
  return std::string(home != nullptr && *home != '\0' ? home : ".") + "/.ros/covoxslam";
}

const std::vector<std::string>& node_option_names() {
  static const std::vector<std::string> names = {"mission_frame",
                                                 "odom_frame",
                                                 "base_frame",
                                                 "use_tf_for_odometry",
                                                 "use_tf_for_extrinsic",
                                                 "T_base_sensor",
                                                 "tf_wait_timeout_s",
                                                 "max_pending_clouds",
                                                 "odometry_buffer_s",
                                                 "odometry_max_gap_s",
                                                 "use_color",
                                                 "use_intensity",
                                                 "intensity_max_value",
                                                 "use_depth_images",
                                                 "use_color_images",
                                                 "depth_pixel_stride",
                                                 "depth_max_m",
                                                 "publish_tf",
                                                 "tf_publish_period_s",
                                                 "visualization_period_s",
                                                 "diagnostics_period_s",
                                                 "publish_esdf_slices",
                                                 "esdf_slice_height_m",
                                                 "active_submap_esdf_slice_period_s",
                                                 "publish_combined_mesh",
                                                 "publish_separated_mesh",
                                                 "drop_log_interval_s",
                                                 "time_jump_policy",
                                                 "time_jump_min_s",
                                                 "mesh_height_color_min_m",
                                                 "mesh_height_color_max_m",
                                                 "output_dir",
                                                 "publish_esdf_pointcloud",
                                                 "esdf_pointcloud_max_distance_m",
                                                 "esdf_pointcloud_max_points",
                                                 "esdf_query_max_points",
                                                 "submap_tf_period_s"};
  return names;
}

NodeOptions read_node_options(const ros::NodeHandle& private_node) {
  const RosParameterSource source(private_node, "ros");
  for (const std::string& key : source.unknown_file_keys(node_option_names())) {
    ROS_WARN_STREAM("covoxslam: unknown parameter "
                    << key << " is ignored (misspelt? docs/parameters.md)");
  }
  NodeOptions options;
  read_frame(source, "mission_frame", &options.mission_frame);
  read_frame(source, "odom_frame", &options.odom_frame);
  read_frame(source, "base_frame", &options.base_frame);
  if (options.mission_frame == options.odom_frame) {
    bad("mission_frame", "must differ from odom_frame ('" + options.odom_frame +
                             "'): the node publishes the correction between them");
  }
  if (options.odom_frame == options.base_frame) bad("base_frame", "must differ from odom_frame");
  read_flag(source, "use_tf_for_odometry", &options.use_tf_for_odometry);
  read_flag(source, "use_tf_for_extrinsic", &options.use_tf_for_extrinsic);
  options.T_base_sensor = read_transform(source, "T_base_sensor", options.T_base_sensor);
  read_amount(source, "tf_wait_timeout_s", &options.tf_wait_timeout_s, true);
  read_count(source, "max_pending_clouds", &options.max_pending_clouds, 1);
  read_amount(source, "odometry_buffer_s", &options.odometry_buffer_s);
  read_amount(source, "odometry_max_gap_s", &options.odometry_max_gap_s);
  read_flag(source, "use_color", &options.use_color);
  read_flag(source, "use_intensity", &options.use_intensity);
  read_amount(source, "intensity_max_value", &options.intensity_max_value);
  read_flag(source, "use_depth_images", &options.use_depth_images);
  read_flag(source, "use_color_images", &options.use_color_images);
  read_count(source, "depth_pixel_stride", &options.depth_pixel_stride, 1);
  read_amount(source, "depth_max_m", &options.depth_max_m);
  read_flag(source, "publish_tf", &options.publish_tf);
  read_amount(source, "tf_publish_period_s", &options.tf_publish_period_s);
  read_amount(source, "visualization_period_s", &options.visualization_period_s);
  read_amount(source, "diagnostics_period_s", &options.diagnostics_period_s);
  read_flag(source, "publish_esdf_slices", &options.publish_esdf_slices);
  double height = options.esdf_slice_height_m;
  if (source.get_number("esdf_slice_height_m", &height)) {
    if (!std::isfinite(height)) bad("esdf_slice_height_m", "must be a finite height in metres");
    options.esdf_slice_height_m = height;
  }
  read_amount(source, "active_submap_esdf_slice_period_s",
              &options.active_submap_esdf_slice_period_s, true);
  read_flag(source, "publish_combined_mesh", &options.publish_combined_mesh);
  read_flag(source, "publish_separated_mesh", &options.publish_separated_mesh);
  read_amount(source, "drop_log_interval_s", &options.drop_log_interval_s, true);
  read_time_and_mesh_options(source, &options);
  if (source.get_text("output_dir", &options.output_dir) && options.output_dir.empty())
    bad("output_dir", "must not be empty (the folder of the file services)");
  read_planner_options(source, &options);
  return options;
}

}  // namespace ros_layer
}  // namespace covox

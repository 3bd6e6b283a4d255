#pragma once
// Conversions between ROS messages and the library's plain types. No logic beyond copying:
// decoding and checking a cloud's bytes is io::decode_point_cloud's job.
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Transform.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <visualization_msgs/Marker.h>
#include <visualization_msgs/MarkerArray.h>

#include "covoxslam/integrators/esdf_queries.h"
#include "covoxslam/io/depth_image_points.h"
#include "covoxslam/io/pointcloud_fields.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/map/mesh_colors.h"
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace ros_layer {

io::PointCloudLayout point_cloud_layout(const sensor_msgs::PointCloud2& cloud);
io::ImageLayout image_layout(const sensor_msgs::Image& image);
io::CameraIntrinsics camera_intrinsics(const sensor_msgs::CameraInfo& info);

Eigen::Isometry3d to_isometry(const geometry_msgs::Transform& transform);
geometry_msgs::Transform to_transform_msg(const Eigen::Isometry3d& pose);
geometry_msgs::Pose to_pose_msg(const Eigen::Isometry3d& pose);

// A triangle list (three points per triangle) in `frame` at `pose`, each point coloured by
// `colors` (one per mesh vertex, e.g. map/mesh_colors.h's display_colors()).
visualization_msgs::Marker mesh_marker(const map::Mesh& mesh, const std::vector<Rgb8>& colors,
                                       const Eigen::Isometry3d& pose, const std::string& frame,
                                       const ros::Time& stamp, const std::string& ns, int id);
// A triangle list of `mesh` (in `frame`, at the identity) with one colour per triangle
// (`face_colors`, e.g. map::shaded_face_colors()): 88 bytes a triangle against 120 with per-vertex
// colours. rviz draws a triangle list with colours unlit, so both sides show the colour.
visualization_msgs::Marker face_colored_mesh_marker(const map::Mesh& mesh,
                                                    const std::vector<Rgb8>& face_colors,
                                                    const std::string& frame,
                                                    const ros::Time& stamp, const std::string& ns,
                                                    int id);
// A DELETE of marker `id` in namespace `ns`.
visualization_msgs::Marker deletion_marker(const std::string& frame, const ros::Time& stamp,
                                           const std::string& ns, int id);

// A DELETEALL, then one LINE_LIST per submap (namespace submap_bounding_boxes, id = submap id)
// holding the 12 edges of its world-frame box.
visualization_msgs::MarkerArray bounding_box_markers(
    const std::vector<pipeline::SubmapInfo>& submaps, const std::string& frame,
    const ros::Time& stamp);
// Submap origins (SPHERE_LIST) and one LINE_LIST per constraint kind between submap origins,
// coloured by kind, in the namespace named after the kind.
visualization_msgs::MarkerArray pose_graph_markers(
    const std::vector<pipeline::SubmapInfo>& submaps,
    const std::vector<pipeline::SubmapConstraint>& constraints, const std::string& frame,
    const ros::Time& stamp);
// x, y, z and intensity (the signed distance in metres), all FLOAT32, unorganised.
sensor_msgs::PointCloud2 slice_cloud(const std::vector<integrators::SlicePoint>& slice,
                                     const std::string& frame, const ros::Time& stamp);

}  // namespace ros_layer
}  // namespace covox

#include "covoxslam/ros/message_conversions.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>

namespace covox {
namespace ros_layer {

io::PointCloudLayout point_cloud_layout(const sensor_msgs::PointCloud2& cloud) {
  io::PointCloudLayout layout;
  layout.width = cloud.width;
  layout.height = cloud.height;
  layout.point_step = cloud.point_step;
  layout.row_step = cloud.row_step;
  layout.is_bigendian = cloud.is_bigendian;
  for (const sensor_msgs::PointField& field : cloud.fields) {
    layout.fields.push_back(
        io::PointFieldDescription{field.name, field.offset, field.datatype, field.count});
  }
  return layout;
}

io::ImageLayout image_layout(const sensor_msgs::Image& image) {
  return io::ImageLayout{image.width, image.height, image.step, image.encoding,
                         image.is_bigendian != 0};
}

io::CameraIntrinsics camera_intrinsics(const sensor_msgs::CameraInfo& info) {
  io::CameraIntrinsics k;
  k.fx = info.K[0];
  k.fy = info.K[4];
  k.cx = info.K[2];
  k.cy = info.K[5];
  k.width = static_cast<int>(info.width);
  k.height = static_cast<int>(info.height);
  return k;
}

Eigen::Isometry3d to_isometry(const geometry_msgs::Transform& transform) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  const Eigen::Quaterniond q(transform.rotation.w, transform.rotation.x, transform.rotation.y,
                             transform.rotation.z);
  // A zero or non-finite quaternion stays non-finite here, so the pipeline's rigidity check
  // rejects it (counted) instead of a normalisation inventing a rotation.
  pose.linear() =
      q.norm() > 0.0 ? q.normalized().toRotationMatrix() : Eigen::Matrix3d::Constant(NAN);
  pose.translation() =
      Eigen::Vector3d(transform.translation.x, transform.translation.y, transform.translation.z);
  return pose;
}

geometry_msgs::Transform to_transform_msg(const Eigen::Isometry3d& pose) {
  geometry_msgs::Transform transform;
  const Eigen::Quaterniond q(pose.linear());
  transform.translation.x = pose.translation().x();
  transform.translation.y = pose.translation().y();
  transform.translation.z = pose.translation().z();
  transform.rotation.x = q.x();
  transform.rotation.y = q.y();
  transform.rotation.z = q.z();
  transform.rotation.w = q.w();
  return transform;
}

geometry_msgs::Pose to_pose_msg(const Eigen::Isometry3d& pose) {
  const geometry_msgs::Transform transform = to_transform_msg(pose);
  geometry_msgs::Pose msg;
  msg.position.x = transform.translation.x;
  msg.position.y = transform.translation.y;
  msg.position.z = transform.translation.z;
  msg.orientation = transform.rotation;
  return msg;
}

namespace {

geometry_msgs::Point point_msg(const Vec3f& p) {
  geometry_msgs::Point point;
  point.x = p.x;
  point.y = p.y;
  point.z = p.z;
  return point;
}

std_msgs::ColorRGBA opaque_color_msg(const Rgb8& c) {
  std_msgs::ColorRGBA color;
  color.r = c.r / 255.0f;
  color.g = c.g / 255.0f;
  color.b = c.b / 255.0f;
  color.a = 1.0f;
  return color;
}

}  // namespace

visualization_msgs::Marker mesh_marker(const map::Mesh& mesh, const std::vector<Rgb8>& colors,
                                       const Eigen::Isometry3d& pose, const std::string& frame,
                                       const ros::Time& stamp, const std::string& ns, int id) {
  visualization_msgs::Marker marker;
  marker.header.frame_id = frame;
  marker.header.stamp = stamp;
  marker.ns = ns;
  marker.id = id;
  marker.type = visualization_msgs::Marker::TRIANGLE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose = to_pose_msg(pose);
  marker.scale.x = marker.scale.y = marker.scale.z = 1.0;
  marker.color.r = marker.color.g = marker.color.b = 0.7f;
  marker.color.a = 1.0f;
  const bool colored = colors.size() == mesh.vertices_m.size();
  marker.points.reserve(mesh.triangles.size());
  if (colored) marker.colors.reserve(mesh.triangles.size());
  for (uint32_t index : mesh.triangles) {
    if (index >= mesh.vertices_m.size()) continue;  // never from the mesher; guards rviz
    marker.points.push_back(point_msg(mesh.vertices_m[index]));
    if (colored) marker.colors.push_back(opaque_color_msg(colors[index]));
  }
  // rviz needs whole triangles.
  marker.points.resize(marker.points.size() / 3 * 3);
  if (colored) marker.colors.resize(marker.points.size());
  return marker;
}

visualization_msgs::Marker deletion_marker(const std::string& frame, const ros::Time& stamp,
                                           const std::string& ns, int id) {
  visualization_msgs::Marker marker;
  marker.header.frame_id = frame;
  marker.header.stamp = stamp;
  marker.ns = ns;
  marker.id = id;
  marker.action = visualization_msgs::Marker::DELETE;
  return marker;
}

visualization_msgs::Marker face_colored_mesh_marker(const map::Mesh& mesh,
                                                    const std::vector<Rgb8>& face_colors,
                                                    const std::string& frame,
                                                    const ros::Time& stamp, const std::string& ns,
                                                    int id) {
  visualization_msgs::Marker marker =
      mesh_marker(map::Mesh(), {}, Eigen::Isometry3d::Identity(), frame, stamp, ns, id);
  const size_t triangles = std::min(mesh.triangle_count(), face_colors.size());
  marker.points.reserve(3 * triangles);
  marker.colors.reserve(triangles);
  for (size_t t = 0; t < triangles; ++t) {
    const uint32_t* corners = &mesh.triangles[3 * t];
    const size_t vertices = mesh.vertices_m.size();
    // Never from the mesher; guards rviz, which needs one colour per whole triangle.
    if (corners[0] >= vertices || corners[1] >= vertices || corners[2] >= vertices) continue;
    for (int c = 0; c < 3; ++c) marker.points.push_back(point_msg(mesh.vertices_m[corners[c]]));
    marker.colors.push_back(opaque_color_msg(face_colors[t]));
  }
  return marker;
}

namespace {

geometry_msgs::Point point_of(const Eigen::Vector3d& p) {
  geometry_msgs::Point point;
  point.x = p.x();
  point.y = p.y();
  point.z = p.z();
  return point;
}

std_msgs::ColorRGBA rgba(float r, float g, float b, float a = 1.0f) {
  std_msgs::ColorRGBA color;
  color.r = r;
  color.g = g;
  color.b = b;
  color.a = a;
  return color;
}

visualization_msgs::Marker line_list(const std::string& frame, const ros::Time& stamp,
                                     const std::string& ns, int id, double width_m,
                                     const std_msgs::ColorRGBA& color) {
  visualization_msgs::Marker marker;
  marker.header.frame_id = frame;
  marker.header.stamp = stamp;
  marker.ns = ns;
  marker.id = id;
  marker.type = visualization_msgs::Marker::LINE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.orientation.w = 1.0;
  marker.scale.x = width_m;
  marker.color = color;
  return marker;
}

}  // namespace

visualization_msgs::MarkerArray bounding_box_markers(
    const std::vector<pipeline::SubmapInfo>& submaps, const std::string& frame,
    const ros::Time& stamp) {
  visualization_msgs::MarkerArray array;
  // The whole set is replaced each time: boxes of removed submaps go with the DELETEALL.
  visualization_msgs::Marker clear;
  clear.header.frame_id = frame;
  clear.header.stamp = stamp;
  clear.ns = "submap_bounding_boxes";
  clear.action = visualization_msgs::Marker::DELETEALL;
  array.markers.push_back(clear);
  for (const pipeline::SubmapInfo& submap : submaps) {
    const Eigen::AlignedBox3d& box = submap.bounding_box_world;
    if (box.isEmpty()) continue;
    visualization_msgs::Marker marker =
        line_list(frame, stamp, "submap_bounding_boxes", static_cast<int>(submap.id), 0.05,
                  rgba(0.2f, 0.6f, 1.0f));
    const Eigen::Vector3d lo = box.min(), hi = box.max();
    auto corner = [&](int i) {
      return Eigen::Vector3d((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                             (i & 4) ? hi.z() : lo.z());
    };
    // The 12 edges join corners differing in exactly one bit.
    for (int a = 0; a < 8; ++a) {
      for (int bit : {1, 2, 4}) {
        const int b = a | bit;
        if (b == a) continue;
        marker.points.push_back(point_of(corner(a)));
        marker.points.push_back(point_of(corner(b)));
      }
    }
    array.markers.push_back(marker);
  }
  return array;
}

visualization_msgs::MarkerArray pose_graph_markers(
    const std::vector<pipeline::SubmapInfo>& submaps,
    const std::vector<pipeline::SubmapConstraint>& constraints, const std::string& frame,
    const ros::Time& stamp) {
  visualization_msgs::MarkerArray array;
  std::map<int64_t, Eigen::Vector3d> origin_of;
  visualization_msgs::Marker nodes;
  nodes.header.frame_id = frame;
  nodes.header.stamp = stamp;
  nodes.ns = "submap_origins";
  nodes.type = visualization_msgs::Marker::SPHERE_LIST;
  nodes.action = visualization_msgs::Marker::ADD;
  nodes.pose.orientation.w = 1.0;
  nodes.scale.x = nodes.scale.y = nodes.scale.z = 0.4;
  nodes.color = rgba(1.0f, 1.0f, 1.0f);
  for (const pipeline::SubmapInfo& submap : submaps) {
    origin_of[submap.id] = submap.T_world_submap.translation();
    nodes.points.push_back(point_of(submap.T_world_submap.translation()));
  }
  array.markers.push_back(nodes);

  const struct {
    pipeline::SubmapConstraintKind kind;
    const char* ns;
    std_msgs::ColorRGBA color;
  } kinds[] = {
      {pipeline::SubmapConstraintKind::kOdometry, "pose_graph_odometry", rgba(0.2f, 0.9f, 0.2f)},
      {pipeline::SubmapConstraintKind::kRegistration, "pose_graph_registration",
       rgba(1.0f, 0.8f, 0.0f)},
      {pipeline::SubmapConstraintKind::kLoopClosure, "pose_graph_loop_closure",
       rgba(1.0f, 0.1f, 0.1f)},
      {pipeline::SubmapConstraintKind::kGaugeAnchor, "pose_graph_gauge_anchor",
       rgba(0.5f, 0.5f, 0.5f, 0.5f)}};
  int id = 0;
  for (const auto& kind : kinds) {
    visualization_msgs::Marker edges = line_list(frame, stamp, kind.ns, id++, 0.08, kind.color);
    for (const pipeline::SubmapConstraint& constraint : constraints) {
      if (constraint.kind != kind.kind || constraint.is_absolute()) continue;
      auto from = origin_of.find(constraint.from_submap), to = origin_of.find(constraint.to_submap);
      if (from == origin_of.end() || to == origin_of.end()) continue;
      edges.points.push_back(point_of(from->second));
      edges.points.push_back(point_of(to->second));
    }
    // An empty LINE_LIST is valid: it clears the kind's edges after a reset.
    array.markers.push_back(edges);
  }
  return array;
}

sensor_msgs::PointCloud2 slice_cloud(const std::vector<integrators::SlicePoint>& slice,
                                     const std::string& frame, const ros::Time& stamp) {
  sensor_msgs::PointCloud2 cloud;
  cloud.header.frame_id = frame;
  cloud.header.stamp = stamp;
  const char* names[] = {"x", "y", "z", "intensity"};
  for (uint32_t i = 0; i < 4; ++i) {
    sensor_msgs::PointField field;
    field.name = names[i];
    field.offset = 4 * i;
    field.datatype = sensor_msgs::PointField::FLOAT32;
    field.count = 1;
    cloud.fields.push_back(field);
  }
  cloud.point_step = 16;
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(slice.size());
  cloud.row_step = cloud.point_step * cloud.width;
  cloud.is_bigendian = false;
  cloud.is_dense = true;
  cloud.data.resize(cloud.row_step);
  uint8_t* out = cloud.data.data();
  for (const integrators::SlicePoint& point : slice) {
    const float values[4] = {point.position_m.x, point.position_m.y, point.position_m.z,
                             point.distance_m};
    std::memcpy(out, values, sizeof(values));
    out += sizeof(values);
  }
  return cloud;
}

}  // namespace ros_layer
}  // namespace covox

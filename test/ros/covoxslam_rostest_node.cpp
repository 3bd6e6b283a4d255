// rostest of the covoxslam nodelet (test/ros/covoxslam_nodelet.test starts it in a nodelet
// manager). This node writes a short bag of a synthetic scene - a LiDAR moving through a room
// with a pillar, its odometry on /tf and its extrinsic on /tf_static, plus one cloud without a
// z field and one in a frame that tf does not know - plays it with `rosbag play --clock`, and
// checks what the nodelet publishes (path, submap poses, meshes, ESDF slice against the room's
// analytic distance, tf, diagnostics counters) and its services (finish, save map / trajectory /
// mesh, reset, load map, generate mesh). Then it goes on as an operator would: after load_map
// and after finish_map more of the flight is played and must be mapped, a late subscriber must
// receive every submap's mesh, and the first bag played again (time going backwards) must be
// mapped after an automatic reset.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <boost/make_shared.hpp>
#include <covoxslam/FilePath.h>
#include <covoxslam/LoopClosure.h>
#include <covoxslam/SubmapPoses.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/Marker.h>
#include <visualization_msgs/MarkerArray.h>

#include "rostest_scene.h"

namespace covox_rostest {

// ---- The synthetic scene ---------------------------------------------------------------------

constexpr int kRings = 24, kColumns = 240;

Eigen::Isometry3d base_pose_at(double t_s) {
  const double s = t_s - kStart_s;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(-3.0 + 0.5 * s, -1.5 + 0.1 * s, 1.2);
  pose.linear() = Eigen::AngleAxisd(0.08 * s, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return pose;
}

Eigen::Isometry3d base_to_lidar() {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(0.1, 0.0, 0.2);
  pose.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return pose;
}

// Distance along the ray to the first surface (room from inside, pillar from outside).
double cast_ray(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction) {
  double t_room = std::numeric_limits<double>::infinity();
  for (int axis = 0; axis < 3; ++axis) {
    if (direction[axis] > 1e-12)
      t_room = std::min(t_room, (kRoomMax[axis] - origin[axis]) / direction[axis]);
    if (direction[axis] < -1e-12)
      t_room = std::min(t_room, (kRoomMin[axis] - origin[axis]) / direction[axis]);
  }
  double t_enter = 0.0, t_exit = std::numeric_limits<double>::infinity();
  for (int axis = 0; axis < 3; ++axis) {
    if (std::abs(direction[axis]) < 1e-12) {
      if (origin[axis] < kPillarMin[axis] || origin[axis] > kPillarMax[axis]) t_exit = -1.0;
      continue;
    }
    double t0 = (kPillarMin[axis] - origin[axis]) / direction[axis];
    double t1 = (kPillarMax[axis] - origin[axis]) / direction[axis];
    if (t0 > t1) std::swap(t0, t1);
    t_enter = std::max(t_enter, t0);
    t_exit = std::min(t_exit, t1);
  }
  if (t_exit >= t_enter && t_enter > 0.0) return std::min(t_room, t_enter);
  return t_room;
}

// Distance from a point inside the room (outside the pillar) to the nearest surface.
double scene_distance(const Eigen::Vector3d& p) {
  double d = std::numeric_limits<double>::infinity();
  for (int axis = 0; axis < 3; ++axis)
    d = std::min({d, p[axis] - kRoomMin[axis], kRoomMax[axis] - p[axis]});
  const Eigen::Vector3d outside =
      (kPillarMin - p).cwiseMax(p - kPillarMax).cwiseMax(Eigen::Vector3d::Zero());
  return std::min(d, outside.norm());
}

// An organised cloud with a scrambled layout: intensity, z, y, x, ring, padding (24 bytes).
sensor_msgs::PointCloud2 make_cloud(double t_s, const std::string& frame, bool drop_z_field) {
  sensor_msgs::PointCloud2 cloud;
  cloud.header.stamp.fromSec(t_s);
  cloud.header.frame_id = frame;
  cloud.height = kRings;
  cloud.width = kColumns;
  cloud.point_step = 24;
  cloud.row_step = cloud.width * cloud.point_step;
  cloud.is_bigendian = false;
  cloud.is_dense = false;
  const struct {
    const char* name;
    uint32_t offset;
    uint8_t type;
  } fields[] = {{"intensity", 0, sensor_msgs::PointField::FLOAT32},
                {"z", 4, sensor_msgs::PointField::FLOAT32},
                {"y", 8, sensor_msgs::PointField::FLOAT32},
                {"x", 12, sensor_msgs::PointField::FLOAT32},
                {"ring", 16, sensor_msgs::PointField::UINT16}};
  for (const auto& f : fields) {
    if (drop_z_field && std::string(f.name) == "z") continue;
    sensor_msgs::PointField field;
    field.name = f.name;
    field.offset = f.offset;
    field.datatype = f.type;
    field.count = 1;
    cloud.fields.push_back(field);
  }
  cloud.data.assign(static_cast<size_t>(cloud.row_step) * cloud.height, 0);
  const Eigen::Isometry3d T_world_lidar = base_pose_at(t_s) * base_to_lidar();
  for (int ring = 0; ring < kRings; ++ring) {
    const double elevation = (-30.0 + 60.0 * ring / (kRings - 1)) * M_PI / 180.0;
    for (int column = 0; column < kColumns; ++column) {
      const double azimuth = 2.0 * M_PI * column / kColumns;
      const Eigen::Vector3d direction_lidar(std::cos(elevation) * std::cos(azimuth),
                                            std::cos(elevation) * std::sin(azimuth),
                                            std::sin(elevation));
      const Eigen::Vector3d direction_world = T_world_lidar.linear() * direction_lidar;
      const double range = cast_ray(T_world_lidar.translation(), direction_world);
      Eigen::Vector3f point = (range * direction_lidar).cast<float>();
      // Every 37th return is missing, as NaN (what organised drivers publish).
      if ((ring * kColumns + column) % 37 == 0)
        point.setConstant(std::numeric_limits<float>::quiet_NaN());
      const float intensity = static_cast<float>(20.0 * range);
      const uint16_t ring_index = static_cast<uint16_t>(ring);
      uint8_t* at = cloud.data.data() + static_cast<size_t>(ring) * cloud.row_step +
                    column * cloud.point_step;
      std::memcpy(at + 0, &intensity, 4);
      std::memcpy(at + 4, &point.z(), 4);
      std::memcpy(at + 8, &point.y(), 4);
      std::memcpy(at + 12, &point.x(), 4);
      std::memcpy(at + 16, &ring_index, 2);
    }
  }
  return cloud;
}

// A forward-looking depth camera (optical frame: z forward, x right, y down) on the base.
constexpr int kDepthWidth = 80, kDepthHeight = 60;
constexpr double kFocal_px = 50.0;

Eigen::Isometry3d base_to_camera() {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(0.2, 0.0, 0.1);
  pose.linear().col(0) = Eigen::Vector3d(0, -1, 0);
  pose.linear().col(1) = Eigen::Vector3d(0, 0, -1);
  pose.linear().col(2) = Eigen::Vector3d(1, 0, 0);
  return pose;
}

sensor_msgs::CameraInfo camera_info(double t_s) {
  sensor_msgs::CameraInfo info;
  info.header.stamp.fromSec(t_s);
  info.header.frame_id = "camera";
  info.width = kDepthWidth;
  info.height = kDepthHeight;
  info.K = {kFocal_px, 0.0, kDepthWidth / 2.0, 0.0, kFocal_px, kDepthHeight / 2.0, 0.0, 0.0, 1.0};
  return info;
}

// Depth in millimetres (16UC1) and a registered bgr8 colour image of the room.
void make_depth_images(double t_s, sensor_msgs::Image* depth, sensor_msgs::Image* color) {
  const Eigen::Isometry3d T_world_camera = base_pose_at(t_s) * base_to_camera();
  for (sensor_msgs::Image* image : {depth, color}) {
    image->header.stamp.fromSec(t_s);
    image->header.frame_id = "camera";
    image->width = kDepthWidth;
    image->height = kDepthHeight;
    image->is_bigendian = 0;
  }
  depth->encoding = "16UC1";
  depth->step = 2 * kDepthWidth;
  depth->data.assign(depth->step * kDepthHeight, 0);
  color->encoding = "bgr8";
  color->step = 3 * kDepthWidth;
  color->data.assign(color->step * kDepthHeight, 0);
  for (int v = 0; v < kDepthHeight; ++v) {
    for (int u = 0; u < kDepthWidth; ++u) {
      const Eigen::Vector3d ray((u - kDepthWidth / 2.0) / kFocal_px,
                                (v - kDepthHeight / 2.0) / kFocal_px, 1.0);
      const Eigen::Vector3d direction_world = T_world_camera.linear() * ray.normalized();
      const double range = cast_ray(T_world_camera.translation(), direction_world);
      const double z_m = range * ray.normalized().z();  // depth is along the optical axis
      const uint16_t millimetres = static_cast<uint16_t>(std::lround(std::min(z_m, 60.0) * 1000.0));
      std::memcpy(depth->data.data() + v * depth->step + 2 * u, &millimetres, 2);
      uint8_t* pixel = color->data.data() + v * color->step + 3 * u;
      pixel[0] = 40;
      pixel[1] = static_cast<uint8_t>(u * 3);
      pixel[2] = static_cast<uint8_t>(v * 4);
    }
  }
}

geometry_msgs::TransformStamped stamped(const Eigen::Isometry3d& pose, const std::string& parent,
                                        const std::string& child, double t_s) {
  geometry_msgs::TransformStamped transform = tf2::eigenToTransform(pose);
  transform.header.stamp.fromSec(t_s);
  transform.header.frame_id = parent;
  transform.child_frame_id = child;
  return transform;
}

// The bag: /tf at 50 Hz, /tf_static (latched), the valid clouds, a cloud without z and one in
// an unknown frame (both between valid clouds).
// covoxslam_nodelet_odometry.test sets ~odometry_as_topic: the odometry then comes as
// nav_msgs/Odometry on /synthetic/odometry instead of tf odom -> base_link.
bool odometry_as_topic() {
  bool value = false;
  ros::NodeHandle("~").getParam("odometry_as_topic", value);
  return value;
}

// covoxslam_nodelet_depth.test sets ~depth_images: the sensor is then a depth camera with a
// colour image and camera info instead of the LiDAR (and there are no bad clouds).
bool depth_images() {
  bool value = false;
  ros::NodeHandle("~").getParam("depth_images", value);
  return value;
}

Eigen::Isometry3d base_to_sensor() { return depth_images() ? base_to_camera() : base_to_lidar(); }

// `clouds` valid clouds from `start_s` on the same path (a later start continues the flight), with
// the bad clouds of the first bag when `bad_clouds`.
void write_bag(const std::string& path, double start_s, int clouds, bool bad_clouds) {
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  auto latched = boost::make_shared<ros::M_string>();
  (*latched)["latching"] = "1";
  (*latched)["callerid"] = "/synthetic_robot";
  // A custom connection header replaces the default one, so it must carry the type too.
  (*latched)["type"] = ros::message_traits::datatype<tf2_msgs::TFMessage>();
  (*latched)["md5sum"] = ros::message_traits::md5sum<tf2_msgs::TFMessage>();
  (*latched)["message_definition"] = ros::message_traits::definition<tf2_msgs::TFMessage>();
  tf2_msgs::TFMessage statics;
  statics.transforms.push_back(stamped(base_to_lidar(), "base_link", "lidar", kStart_s));
  statics.transforms.push_back(stamped(base_to_camera(), "base_link", "camera", kStart_s));
  bag.write("/tf_static", ros::Time(start_s), statics, latched);
  const double end_s = start_s + clouds * kCloudPeriod_s + 0.5;
  for (int k = 0; start_s + 0.02 * k <= end_s; ++k) {
    const double t = start_s + 0.02 * k;
    if (odometry_as_topic()) {
      nav_msgs::Odometry odometry;
      odometry.header.stamp.fromSec(t);
      odometry.header.frame_id = "odom";
      odometry.child_frame_id = "base_link";
      const geometry_msgs::TransformStamped pose = stamped(base_pose_at(t), "odom", "base_link", t);
      odometry.pose.pose.position.x = pose.transform.translation.x;
      odometry.pose.pose.position.y = pose.transform.translation.y;
      odometry.pose.pose.position.z = pose.transform.translation.z;
      odometry.pose.pose.orientation = pose.transform.rotation;
      bag.write("/synthetic/odometry", ros::Time(t), odometry);
    } else {
      tf2_msgs::TFMessage message;
      message.transforms.push_back(stamped(base_pose_at(t), "odom", "base_link", t));
      bag.write("/tf", ros::Time(t), message);
    }
  }
  for (int k = 0; k < clouds; ++k) {
    const double t = start_s + 0.1 + kCloudPeriod_s * k;
    if (depth_images()) {
      sensor_msgs::Image depth, color;
      make_depth_images(t, &depth, &color);
      bag.write("/synthetic/depth/image", ros::Time(t), depth);
      bag.write("/synthetic/depth/camera_info", ros::Time(t), camera_info(t));
      bag.write("/synthetic/color/image", ros::Time(t), color);
      continue;
    }
    bag.write("/synthetic/points", ros::Time(t), make_cloud(t, "lidar", false));
    if (!bad_clouds) continue;
    if (k == 3)
      bag.write("/synthetic/points", ros::Time(t + 0.2), make_cloud(t + 0.2, "lidar", true));
    if (k == 6)
      bag.write("/synthetic/points", ros::Time(t + 0.2), make_cloud(t + 0.2, "nowhere", false));
  }
  bag.close();
}

// Plays `bag_path` into the nodelet with the clock (-d: wait after advertising so that the
// nodelet is connected); returns rosbag's exit status, `log` receives what it said.
int play_bag(const fs::path& folder, const std::string& bag_path, std::string* log) {
  const std::string play =
      "rosbag play --clock -q -d 2 " + bag_path + " > " + (folder / "play.log").string() + " 2>&1";
  const int status = std::system(play.c_str());
  std::ifstream file((folder / "play.log").string());
  log->assign((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  return status;
}

// NaN / infinite points among the clouds the first bag holds (the valid ones and the one in an
// unknown frame; the cloud without z is refused before its points are read).
int64_t non_finite_points_in_first_bag() {
  int64_t count = 0;
  for (int k = 0; k < kClouds; ++k) {
    const double t = kStart_s + 0.1 + kCloudPeriod_s * k;
    std::vector<sensor_msgs::PointCloud2> clouds = {make_cloud(t, "lidar", false)};
    if (k == 6) clouds.push_back(make_cloud(t + 0.2, "nowhere", false));
    for (const sensor_msgs::PointCloud2& cloud : clouds) {
      for (size_t offset = 0; offset < cloud.data.size(); offset += cloud.point_step) {
        float xyz[3];
        std::memcpy(xyz, cloud.data.data() + offset + 4, sizeof(xyz));
        if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2])) ++count;
      }
    }
  }
  return count;
}

std::string ns(const std::string& name) { return "/covoxslam/" + name; }

bool call_trigger(const std::string& name, std::string* message) {
  std_srvs::Trigger trigger;
  if (!ros::service::call(ns(name), trigger)) {
    *message = "the call failed";
    return false;
  }
  *message = trigger.response.message;
  return trigger.response.success;
}

bool call_file(const std::string& name, const std::string& path, std::string* message,
               bool overwrite) {
  covoxslam::FilePath file;
  file.request.file_path = path;
  file.request.overwrite = overwrite;
  if (!ros::service::call(ns(name), file)) {
    *message = "the call failed";
    return false;
  }
  *message = file.response.message;
  return file.response.success;
}

}  // namespace covox_rostest

namespace {

using namespace covox_rostest;

// ---- What the nodelet publishes --------------------------------------------------------------

struct Latest {
  std::mutex mutex;
  nav_msgs::Path path;
  covoxslam::SubmapPoses submaps;
  visualization_msgs::Marker combined_mesh;
  // Markers by (namespace, id): a submap's mesh is one marker with the submap's id.
  std::map<std::pair<std::string, int>, visualization_msgs::Marker> separated_meshes;
  std::map<int, int> mesh_sends;  // in how many messages each submap's mesh came
  sensor_msgs::PointCloud2 esdf_slice;
  sensor_msgs::PointCloud2 active_esdf_slice;
  std::map<int, visualization_msgs::Marker> boxes;
  std::map<std::string, std::string> diagnostics;
  int path_messages = 0, submap_messages = 0, mesh_messages = 0, slice_messages = 0,
      diagnostics_messages = 0;
};

Latest latest;

// Submap id -> the points of all its mesh markers.
using MeshMarkers = std::map<std::pair<std::string, int>, visualization_msgs::Marker>;
std::map<int, size_t> points_per_submap(const MeshMarkers& markers) {
  std::map<int, size_t> points;
  for (const auto& marker : markers) points[marker.first.second] += marker.second.points.size();
  return points;
}

// Applies one ~separated_mesh message to `markers`; returns the submaps it sent a mesh of.
std::set<int> apply_mesh_message(const visualization_msgs::MarkerArray& message,
                                 MeshMarkers* markers) {
  std::set<int> sent;
  for (const auto& marker : message.markers) {
    if (marker.action == visualization_msgs::Marker::DELETEALL) markers->clear();
    if (marker.action == visualization_msgs::Marker::DELETE) markers->erase({marker.ns, marker.id});
    if (marker.action == visualization_msgs::Marker::ADD) {
      (*markers)[{marker.ns, marker.id}] = marker;
      sent.insert(marker.id);
    }
  }
  return sent;
}

// Waits (wall time) until `condition` holds under the lock.
bool wait_for(const std::function<bool()>& condition, double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    {
      std::lock_guard<std::mutex> lock(latest.mutex);
      if (condition()) return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  std::lock_guard<std::mutex> lock(latest.mutex);
  return condition();
}

int64_t diagnostic_value(const std::string& key) {
  auto it = latest.diagnostics.find(key);
  return it == latest.diagnostics.end() ? -1 : std::stoll(it->second);
}

// A bad request is answered, not crashed on: names outside ~ros/output_dir are refused, and the
// existing `map_path` is kept unless overwrite is asked for.
void expect_bad_file_requests_refused(const fs::path& outside_folder, const std::string& map_path) {
  std::string message;
  EXPECT_FALSE(call_file("save_map", "", &message));
  EXPECT_FALSE(call_file("load_map", "missing.covoxmap", &message));
  EXPECT_NE(message.find("missing.covoxmap"), std::string::npos) << message;
  const std::string outside = (outside_folder / "outside.covoxmap").string();
  EXPECT_FALSE(call_file("save_map", outside, &message, true));
  EXPECT_NE(message.find("absolute"), std::string::npos) << message;
  EXPECT_FALSE(fs::exists(outside));
  EXPECT_FALSE(call_file("save_mesh", "../mesh.ply", &message, true));
  EXPECT_NE(message.find("contains '..'"), std::string::npos) << message;
  EXPECT_FALSE(call_file("load_map", "/etc/passwd", &message));
  EXPECT_NE(message.find("refused"), std::string::npos) << message;
  const auto map_bytes = fs::file_size(map_path);
  EXPECT_FALSE(call_file("save_map", "map.covoxmap", &message));
  EXPECT_NE(message.find("overwrite"), std::string::npos) << message;
  EXPECT_EQ(fs::file_size(map_path), map_bytes);
}

// An ESDF slice at 1.0 m: distances match the room's analytic distance where both are well inside.
// Returns how many cells were compared; `good` receives how many were within 0.3 m.
int compare_slice_with_room(const sensor_msgs::PointCloud2& slice, int* good) {
  *good = 0;
  if (slice.point_step != 16u || slice.fields.size() != 4u || slice.fields[3].name != "intensity") {
    ADD_FAILURE() << "slice layout: point step " << slice.point_step << ", " << slice.fields.size()
                  << " fields";
    return 0;
  }
  int checked = 0;
  for (uint32_t i = 0; i < slice.width; ++i) {
    float v[4];
    std::memcpy(v, slice.data.data() + 16 * i, 16);
    EXPECT_NEAR(v[2], 1.0, 1e-4);
    const Eigen::Vector3d p(v[0], v[1], v[2]);
    const bool inside_room =
        (p.array() > kRoomMin.array()).all() && (p.array() < kRoomMax.array()).all();
    const bool in_pillar =
        (p.array() > kPillarMin.array()).all() && (p.array() < kPillarMax.array()).all();
    if (!inside_room || in_pillar) continue;
    const double truth = std::min(scene_distance(p), 2.0);  // esdf_max_distance_m
    // A depth camera sees a wedge: far from a wall, the nearest true surface may be one it
    // never saw, so there only cells close to a wall are compared.
    if (truth < 0.3 || truth > (depth_images() ? 0.8 : 1.8)) continue;
    ++checked;
    if (std::abs(v[3] - truth) < 0.3) ++*good;
  }
  return checked;
}

// A cloud 50 s older than anything tf (or the odometry buffer) holds is dropped as "pose
// unavailable" at once, not counted as a tf timeout, and does not count as time going backwards.
void expect_old_cloud_dropped_at_once(ros::NodeHandle& node) {
  const int64_t unavailable = diagnostic_value("clouds_dropped_pose_unavailable");
  const int64_t timeouts = diagnostic_value("clouds_dropped_tf_timeout");
  ros::Publisher points = node.advertise<sensor_msgs::PointCloud2>("/synthetic/points", 1);
  const auto connected = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (points.getNumSubscribers() == 0 && std::chrono::steady_clock::now() < connected)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  points.publish(make_cloud(kStart_s - 50.0, "lidar", false));
  EXPECT_TRUE(wait_for(
      [&] { return diagnostic_value("clouds_dropped_pose_unavailable") == unavailable + 1; }, 10.0))
      << "pose unavailable: " << diagnostic_value("clouds_dropped_pose_unavailable") << " (was "
      << unavailable << "), tf timeouts " << diagnostic_value("clouds_dropped_tf_timeout");
  std::lock_guard<std::mutex> lock(latest.mutex);
  EXPECT_EQ(diagnostic_value("clouds_dropped_tf_timeout"), timeouts);
  EXPECT_EQ(diagnostic_value("automatic_resets"), 0);
}

// Sum of the scans in the submaps that were not loaded from a map file (the submap poses do not
// say which were; their ids do: loaded ids are below `first_new_id`).
int64_t scans_in_submaps_from(int64_t first_new_id) {
  int64_t scans = 0;
  for (const auto& submap : latest.submaps.submaps) {
    if (submap.id >= first_new_id) scans += submap.scans;
  }
  return scans;
}

// A subscriber that connects late (here: after several maps, finishes and loads). roscpp connects
// a topic once per process, so the test's first subscription is shut down before: the late one
// then opens a connection of its own, as a late rviz or a second node does.
struct LateSubscriber {
  std::mutex mutex;
  MeshMarkers meshes;
};
LateSubscriber late;

// A new ~separated_mesh subscriber receives every submap's mesh, each in its submap's frame
// (frame-locked), never black, as large as what the first subscriber holds, and the submap frames
// on tf are the submaps' corrected poses.
void expect_late_subscriber_gets_every_mesh(ros::NodeHandle& node, ros::Subscriber* first) {
  std::map<int, covoxslam::SubmapPose> submaps;
  std::map<int, size_t> points_first_subscriber;
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    for (const auto& submap : latest.submaps.submaps) {
      if (submap.mesh_triangles > 0) submaps[static_cast<int>(submap.id)] = submap;
    }
    points_first_subscriber = points_per_submap(latest.separated_meshes);
  }
  ASSERT_GT(submaps.size(), 2u);
  first->shutdown();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  auto on_mesh = [](const visualization_msgs::MarkerArray::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(late.mutex);
    apply_mesh_message(*m, &late.meshes);
  };
  ros::Subscriber subscriber =
      node.subscribe<visualization_msgs::MarkerArray>(ns("separated_mesh"), 10, +on_mesh);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(15);
  auto has_all = [&] {
    std::lock_guard<std::mutex> lock(late.mutex);
    const std::map<int, size_t> points = points_per_submap(late.meshes);
    for (const auto& submap : submaps) {
      if (!points.count(submap.first)) return false;
    }
    return true;
  };
  while (!has_all() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_TRUE(has_all()) << "the late subscriber has " << late.meshes.size() << " of "
                         << submaps.size() << " submap meshes";
  tf2_ros::Buffer tf_buffer;
  tf2_ros::TransformListener tf_listener(tf_buffer);
  // Polled in wall time: the simulated clock stands still after the bag, so a tf wait with a
  // timeout would never end.
  auto has_frames = [&] {
    for (const auto& submap : submaps) {
      if (!tf_buffer.canTransform("mission", "submap_" + std::to_string(submap.first),
                                  ros::Time(0)))
        return false;
    }
    return true;
  };
  const auto tf_deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!has_frames() && std::chrono::steady_clock::now() < tf_deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_TRUE(has_frames()) << "tf has frames: " << tf_buffer.allFramesAsString();
  std::lock_guard<std::mutex> lock(late.mutex);
  for (const auto& entry : late.meshes) {
    const visualization_msgs::Marker& marker = entry.second;
    const std::string frame = "submap_" + std::to_string(marker.id);
    EXPECT_EQ(marker.header.frame_id, frame);
    EXPECT_TRUE(marker.frame_locked);
    EXPECT_EQ(marker.type, visualization_msgs::Marker::TRIANGLE_LIST);
    EXPECT_EQ(marker.points.size() % 3, 0u);
    // Per-vertex colours (fused), or one per triangle (by height, shaded): never black. With
    // colours rviz draws a triangle list unlit, so neither side of a face is black either.
    ASSERT_TRUE(marker.colors.size() == marker.points.size() ||
                marker.colors.size() * 3 == marker.points.size())
        << frame << ": " << marker.colors.size() << " colours for " << marker.points.size()
        << " points";
    int black = 0;
    for (const auto& color : marker.colors) black += color.r + color.g + color.b == 0.0f;
    EXPECT_EQ(black, 0) << frame;
  }
  const std::map<int, size_t> late_points = points_per_submap(late.meshes);
  for (const auto& submap : submaps) {
    const std::string frame = "submap_" + std::to_string(submap.first);
    EXPECT_EQ(late_points.at(submap.first), points_first_subscriber[submap.first]) << frame;
    geometry_msgs::TransformStamped pose;
    ASSERT_NO_THROW(pose = tf_buffer.lookupTransform("mission", frame, ros::Time(0))) << frame;
    EXPECT_NEAR(pose.transform.translation.x, submap.second.pose.position.x, 2e-3) << frame;
    EXPECT_NEAR(pose.transform.translation.y, submap.second.pose.position.y, 2e-3) << frame;
    EXPECT_NEAR(pose.transform.translation.z, submap.second.pose.position.z, 2e-3) << frame;
  }
}

// After the main test's load_map: more of the flight mapped after load_map and after finish_map,
// a late subscriber given every submap's mesh, and the first bag played again mapped after an
// automatic reset.
void operator_goes_on(ros::NodeHandle& node, ros::Subscriber* separated_meshes,
                      const fs::path& folder, size_t loaded_count) {
  constexpr int kMoreClouds = 6;
  // Each continuation starts after the previous bag's end, so the clock only moves forward.
  const double second_start_s = kStart_s + kClouds * kCloudPeriod_s + 1.0;
  const double third_start_s = second_start_s + kMoreClouds * kCloudPeriod_s + 1.0;
  const int64_t added_before = diagnostic_value("scans_added");
  int64_t first_new_id = 0;
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    for (const auto& submap : latest.submaps.submaps)
      first_new_id = std::max<int64_t>(first_new_id, submap.id + 1);
  }
  std::string log, message;

  // load_map -> more clouds mapped, into new submaps after the loaded ones.
  const std::string second = (folder / "second.bag").string();
  write_bag(second, second_start_s, kMoreClouds, false);
  ASSERT_EQ(play_bag(folder, second, &log), 0) << log;
  EXPECT_TRUE(wait_for(
      [&] {
        return diagnostic_value("scans_added") == added_before + kMoreClouds &&
               latest.submaps.submaps.size() > loaded_count &&
               latest.path.poses.size() == static_cast<size_t>(kMoreClouds);
      },
      20.0))
      << "after load_map: scans added " << diagnostic_value("scans_added") << " (was "
      << added_before << "), " << latest.submaps.submaps.size() << " submaps (" << loaded_count
      << " loaded), path " << latest.path.poses.size();

  // finish_map -> every scan so far is in a finished submap, and more clouds are mapped after.
  ASSERT_TRUE(call_trigger("finish_map", &message)) << message;
  ASSERT_TRUE(wait_for([&] { return scans_in_submaps_from(first_new_id) == kMoreClouds; }, 10.0))
      << scans_in_submaps_from(first_new_id) << " scans in finished new submaps";
  size_t finished_count = 0;
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    finished_count = latest.submaps.submaps.size();
  }
  const std::string third = (folder / "third.bag").string();
  write_bag(third, third_start_s, kMoreClouds, false);
  ASSERT_EQ(play_bag(folder, third, &log), 0) << log;
  EXPECT_TRUE(wait_for(
      [&] {
        return diagnostic_value("scans_added") == added_before + 2 * kMoreClouds &&
               latest.submaps.submaps.size() > finished_count &&
               latest.path.poses.size() == static_cast<size_t>(2 * kMoreClouds);
      },
      20.0))
      << "after finish_map: scans added " << diagnostic_value("scans_added") << ", "
      << latest.submaps.submaps.size() << " submaps (" << finished_count << " when finished), path "
      << latest.path.poses.size();
  EXPECT_EQ(diagnostic_value("automatic_resets"), 0);
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    EXPECT_EQ(latest.diagnostics["state"], "mapping");
    // The submaps mapped since load_map moved with each optimisation, yet each one's triangles
    // came once: moving a submap moves its frame on tf.
    int new_meshes = 0;
    for (const auto& sends : latest.mesh_sends) {
      if (sends.first < first_new_id) continue;
      ++new_meshes;
      EXPECT_EQ(sends.second, 1) << "submap " << sends.first << "'s mesh came " << sends.second
                                 << " times";
    }
    EXPECT_GE(new_meshes, 2);
  }

  expect_late_subscriber_gets_every_mesh(node, separated_meshes);

  // The first bag played again: the clock jumps back, the map is reset automatically and the
  // second play is mapped.
  const int64_t added_before_replay = diagnostic_value("scans_added");
  ASSERT_EQ(play_bag(folder, (folder / "synthetic.bag").string(), &log), 0) << log;
  EXPECT_TRUE(wait_for(
      [&] {
        return diagnostic_value("automatic_resets") == 1 &&
               diagnostic_value("time_jumps_backwards") == 1 &&
               diagnostic_value("scans_added") == added_before_replay + kClouds &&
               latest.path.poses.size() == static_cast<size_t>(kClouds);
      },
      25.0))
      << "replay: automatic resets " << diagnostic_value("automatic_resets") << ", time jumps "
      << diagnostic_value("time_jumps_backwards") << ", scans added "
      << diagnostic_value("scans_added") << " (was " << added_before_replay << "), path "
      << latest.path.poses.size() << "; rosbag play said: " << log;
  std::lock_guard<std::mutex> lock(latest.mutex);
  for (int k = 0; k < kClouds && k < static_cast<int>(latest.path.poses.size()); ++k) {
    EXPECT_NEAR(latest.path.poses[k].header.stamp.toSec(), kStart_s + 0.1 + kCloudPeriod_s * k,
                1e-6);
  }
}

class CovoxSlamNodeletTest : public ::testing::Test {
 protected:
  void SetUp() override {
    folder_ = fs::temp_directory_path() / ("covoxslam_rostest_" + std::to_string(::getpid()));
    fs::create_directories(folder_);
  }
  void TearDown() override { fs::remove_all(folder_); }
  fs::path folder_;
};

TEST_F(CovoxSlamNodeletTest, MapsABagAndServesTheMap) {
  ros::NodeHandle node;
  auto on_path = [](const nav_msgs::Path::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    latest.path = *m;
    ++latest.path_messages;
  };
  auto on_submaps = [](const covoxslam::SubmapPoses::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    latest.submaps = *m;
    ++latest.submap_messages;
  };
  auto on_combined = [](const visualization_msgs::Marker::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    if (m->action == visualization_msgs::Marker::ADD) latest.combined_mesh = *m;
    ++latest.mesh_messages;
  };
  auto on_separated = [](const visualization_msgs::MarkerArray::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    for (int id : apply_mesh_message(*m, &latest.separated_meshes)) ++latest.mesh_sends[id];
  };
  auto on_slice = [](const sensor_msgs::PointCloud2::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    latest.esdf_slice = *m;
    ++latest.slice_messages;
  };
  // diagnostic_updater's status of the node on /diagnostics: "<node name>: slam".
  auto on_diagnostics = [](const diagnostic_msgs::DiagnosticArray::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    for (const auto& status : m->status) {
      if (status.name != "covoxslam: slam") continue;
      for (const auto& value : status.values) latest.diagnostics[value.key] = value.value;
      ++latest.diagnostics_messages;
    }
  };
  ros::Subscriber s1 = node.subscribe<nav_msgs::Path>(ns("pose_history"), 5, +on_path);
  ros::Subscriber s2 = node.subscribe<covoxslam::SubmapPoses>(ns("submap_poses"), 5, +on_submaps);
  ros::Subscriber s3 =
      node.subscribe<visualization_msgs::Marker>(ns("combined_mesh"), 5, +on_combined);
  ros::Subscriber s4 =
      node.subscribe<visualization_msgs::MarkerArray>(ns("separated_mesh"), 50, +on_separated);
  ros::Subscriber s5 = node.subscribe<sensor_msgs::PointCloud2>(ns("esdf_slice"), 5, +on_slice);
  ros::Subscriber s6 =
      node.subscribe<diagnostic_msgs::DiagnosticArray>("/diagnostics", 5, +on_diagnostics);
  auto on_active_slice = [](const sensor_msgs::PointCloud2::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    latest.active_esdf_slice = *m;
  };
  ros::Subscriber s7 =
      node.subscribe<sensor_msgs::PointCloud2>(ns("active_submap_esdf_slice"), 5, +on_active_slice);
  auto on_boxes = [](const visualization_msgs::MarkerArray::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    for (const auto& marker : m->markers) {
      if (marker.action == visualization_msgs::Marker::DELETEALL) latest.boxes.clear();
      if (marker.action == visualization_msgs::Marker::ADD) latest.boxes[marker.id] = marker;
    }
  };
  ros::Subscriber s8 =
      node.subscribe<visualization_msgs::MarkerArray>(ns("submap_bounding_boxes"), 5, +on_boxes);
  tf2_ros::Buffer tf_buffer;
  tf2_ros::TransformListener tf_listener(tf_buffer);

  ASSERT_TRUE(ros::service::waitForService(ns("finish_map"), ros::Duration(60.0)))
      << "the nodelet did not come up (see its log above)";

  // Play the bag into the nodelet.
  const std::string bag_path = (folder_ / "synthetic.bag").string();
  write_bag(bag_path);
  std::string play_log;
  ASSERT_EQ(play_bag(folder_, bag_path, &play_log), 0) << "rosbag play failed:\n" << play_log;

  // The bad clouds are counted: one without z, one in a frame tf does not know (after the
  // tf wait timeout). Every valid cloud reached the SLAM system.
  const int64_t bad_clouds = depth_images() ? 0 : 1;
  EXPECT_TRUE(wait_for(
      [&] {
        return diagnostic_value("clouds_dropped_bad_layout") == bad_clouds &&
               diagnostic_value("clouds_dropped_unknown_frame") == bad_clouds &&
               diagnostic_value("images_dropped_bad") == 0 &&
               diagnostic_value("scans_added") == kClouds;
      },
      20.0))
      << "rosbag play said: " << play_log << "\nclouds received "
      << diagnostic_value("clouds_received") << ", bad layout "
      << diagnostic_value("clouds_dropped_bad_layout") << ", unknown frame "
      << diagnostic_value("clouds_dropped_unknown_frame") << ", scans added "
      << diagnostic_value("scans_added");
  if (!depth_images()) {
    // NaN points inside valid clouds are dropped and counted, each one.
    EXPECT_TRUE(wait_for(
        [] {
          return diagnostic_value("points_dropped_non_finite") == non_finite_points_in_first_bag();
        },
        5.0))
        << diagnostic_value("points_dropped_non_finite") << " non-finite points counted, "
        << non_finite_points_in_first_bag() << " sent";
    expect_old_cloud_dropped_at_once(node);
  }

  // A loop closure between scans of the first and the last submap, with the true relative
  // sensor pose: it waits for its submaps and enters the pose graph.
  {
    ros::Publisher loop_closures =
        node.advertise<covoxslam::LoopClosure>("/loop_closure_input", 1, true);
    const double from_s = kStart_s + 0.1 + kCloudPeriod_s * 1,
                 to_s = kStart_s + 0.1 + kCloudPeriod_s * 10;
    covoxslam::LoopClosure closure;
    closure.from_timestamp.fromSec(from_s);
    closure.to_timestamp.fromSec(to_s);
    const Eigen::Isometry3d T_from_to = (base_pose_at(from_s) * base_to_sensor()).inverse() *
                                        (base_pose_at(to_s) * base_to_sensor());
    closure.transform = tf2::eigenToTransform(T_from_to).transform;
    for (int i = 0; i < 6; ++i) closure.information[7 * i] = 100.0;
    loop_closures.publish(closure);
    EXPECT_TRUE(wait_for([] { return diagnostic_value("loop_closures_received") == 1; }, 10.0))
        << "loop closures received: " << diagnostic_value("loop_closures_received");
  }

  // The active submap's slice (published while mapping, from a copy of its blocks): the room's
  // distances too, before finish_map turns the active submap into a finished one.
  ASSERT_TRUE(wait_for([] { return latest.active_esdf_slice.width > 30; }, 15.0))
      << "active submap slice: " << latest.active_esdf_slice.width << " cells";
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    int good = 0;
    const int checked = compare_slice_with_room(latest.active_esdf_slice, &good);
    EXPECT_GT(checked, depth_images() ? 10 : 30);
    EXPECT_GT(good, 0.9 * checked)
        << good << " of " << checked << " active slice distances within 0.3 m";
  }

  std::string message;
  ASSERT_TRUE(call_trigger("finish_map", &message)) << message;
  EXPECT_TRUE(wait_for([] { return diagnostic_value("loop_closures_added") == 1; }, 10.0))
      << "loop closures added: " << diagnostic_value("loop_closures_added");

  // Path: one corrected pose per valid cloud, close to the simulated sensor poses.
  ASSERT_TRUE(wait_for([] { return latest.path.poses.size() == kClouds; }, 20.0))
      << "path has " << latest.path.poses.size() << " poses";
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    EXPECT_EQ(latest.path.header.frame_id, "mission");
    for (int k = 0; k < kClouds; ++k) {
      const geometry_msgs::PoseStamped& pose = latest.path.poses[k];
      const double t = kStart_s + 0.1 + kCloudPeriod_s * k;
      EXPECT_NEAR(pose.header.stamp.toSec(), t, 1e-6);
      const Eigen::Vector3d truth = (base_pose_at(t) * base_to_sensor()).translation();
      EXPECT_NEAR(pose.pose.position.x, truth.x(), 0.3) << "pose " << k;
      EXPECT_NEAR(pose.pose.position.y, truth.y(), 0.3) << "pose " << k;
      EXPECT_NEAR(pose.pose.position.z, truth.z(), 0.3) << "pose " << k;
    }
  }

  // Submaps: 5.5 s of clouds with a submap every 2 s.
  ASSERT_TRUE(wait_for([] { return latest.submaps.submaps.size() >= 3; }, 10.0))
      << latest.submaps.submaps.size() << " submaps";
  size_t submap_count = 0;
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    submap_count = latest.submaps.submaps.size();
    int64_t scans = 0;
    for (const auto& submap : latest.submaps.submaps) {
      scans += submap.scans;
      EXPECT_GT(submap.mesh_triangles, 0) << "submap " << submap.id;
    }
    EXPECT_EQ(scans, kClouds);
  }

  // Bounding boxes: one LINE_LIST of 12 edges per submap, around that submap's origin.
  ASSERT_TRUE(wait_for([&] { return latest.boxes.size() == submap_count; }, 10.0))
      << latest.boxes.size() << " boxes for " << submap_count << " submaps";
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    for (const auto& submap : latest.submaps.submaps) {
      ASSERT_TRUE(latest.boxes.count(static_cast<int>(submap.id)))
          << "no box for submap " << submap.id;
      const visualization_msgs::Marker& box = latest.boxes[static_cast<int>(submap.id)];
      EXPECT_EQ(box.type, visualization_msgs::Marker::LINE_LIST);
      ASSERT_EQ(box.points.size(), 24u);
      Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = Eigen::Vector3d::Constant(-1e9);
      for (const auto& p : box.points) {
        lo = lo.cwiseMin(Eigen::Vector3d(p.x, p.y, p.z));
        hi = hi.cwiseMax(Eigen::Vector3d(p.x, p.y, p.z));
      }
      // The submap's first sensor pose sees its own surroundings: its origin lies in its box.
      const Eigen::Vector3d origin(submap.pose.position.x, submap.pose.position.y,
                                   submap.pose.position.z);
      EXPECT_TRUE((origin.array() >= lo.array() - 1e-6).all() &&
                  (origin.array() <= hi.array() + 1e-6).all())
          << "submap " << submap.id << " origin outside its box";
    }
  }

  // Meshes: the combined one and one marker per submap, whole triangles. The two topics arrive
  // one after the other (and the node re-meshes while clouds come in), so the test waits for a
  // pair from the same update: on a loaded 2-core machine it once read a combined mesh of
  // 81483 points against separated ones of 126237 from a later update.
  const auto separated_points_now = [] {
    size_t points = 0;
    for (const auto& marker : latest.separated_meshes) points += marker.second.points.size();
    return points;
  };
  if (!wait_for(
          [&] {
            return !latest.combined_mesh.points.empty() &&
                   points_per_submap(latest.separated_meshes).size() == submap_count &&
                   separated_points_now() == latest.combined_mesh.points.size();
          },
          10.0)) {
    std::lock_guard<std::mutex> lock(latest.mutex);
    FAIL() << "no consistent meshes: combined " << latest.combined_mesh.points.size()
           << " points, separated " << separated_points_now() << " points in "
           << points_per_submap(latest.separated_meshes).size() << " submap meshes for "
           << submap_count << " submaps";
  }
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    EXPECT_EQ(latest.combined_mesh.type, visualization_msgs::Marker::TRIANGLE_LIST);
    EXPECT_EQ(latest.combined_mesh.points.size() % 3, 0u);
    EXPECT_EQ(separated_points_now(), latest.combined_mesh.points.size());
    // Mesh vertices lie on the scene's surfaces (within a voxel).
    int far = 0;
    for (const auto& p : latest.combined_mesh.points) {
      // Negative outside the room: a vertex just behind a wall is still on it.
      if (std::abs(scene_distance(Eigen::Vector3d(p.x, p.y, p.z))) > 0.25) ++far;
    }
    EXPECT_LT(far, static_cast<int>(latest.combined_mesh.points.size() / 20))
        << far << " vertices off the surfaces";
  }

  // ESDF slice at 1.0 m: distances match the room's analytic distance where both are well inside.
  ASSERT_TRUE(wait_for([] { return latest.esdf_slice.width > 100; }, 10.0));
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    int good = 0;
    const int checked = compare_slice_with_room(latest.esdf_slice, &good);
    EXPECT_GT(checked, depth_images() ? 30 : 100);
    EXPECT_GT(good, 0.9 * checked)
        << good << " of " << checked << " slice distances within 0.3 m of the truth";
  }

  // tf: mission -> odom is published (near identity: the odometry here is exact).
  geometry_msgs::TransformStamped correction;
  ASSERT_NO_THROW(
      correction = tf_buffer.lookupTransform("mission", "odom", ros::Time(0), ros::Duration(5.0)));
  EXPECT_NEAR(correction.transform.translation.x, 0.0, 0.3);
  EXPECT_NEAR(correction.transform.translation.y, 0.0, 0.3);

  // Saving: map, trajectory (one TUM line per scan), mesh (a PLY with faces), by names in the
  // node's ~ros/output_dir (the .test file sets it; earlier runs' files are replaced).
  std::string output_dir;
  ASSERT_TRUE(ros::param::get(ns("ros/output_dir"), output_dir));
  const std::string map_path = output_dir + "/map.covoxmap";
  const std::string trajectory_path = output_dir + "/trajectory.tum";
  const std::string mesh_path = output_dir + "/mesh.ply";
  ASSERT_TRUE(call_file("save_map", "map.covoxmap", &message, true)) << message;
  EXPECT_GT(fs::file_size(map_path), 1000u);
  EXPECT_TRUE(call_file("save_trajectory", "trajectory.tum", &message, true)) << message;
  {
    std::ifstream file(trajectory_path);
    std::string line;
    int lines = 0;
    while (std::getline(file, line)) {
      if (!line.empty() && line[0] != '#') ++lines;
    }
    EXPECT_EQ(lines, kClouds);
  }
  EXPECT_TRUE(call_file("save_mesh", "mesh.ply", &message, true)) << message;
  {
    std::ifstream file(mesh_path, std::ios::binary);
    std::string header((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
    const size_t face = header.find("element face ");
    ASSERT_NE(face, std::string::npos);
    EXPECT_GT(std::stol(header.substr(face + 13)), 100);
  }
  expect_bad_file_requests_refused(folder_, map_path);

  // Reset empties the map; loading the saved map brings the submaps and their meshes back.
  ASSERT_TRUE(call_trigger("reset", &message)) << message;
  EXPECT_TRUE(wait_for(
      [] { return latest.submaps.submaps.empty() && latest.separated_meshes.empty(); }, 10.0));
  ASSERT_TRUE(call_file("load_map", "map.covoxmap", &message)) << message;
  EXPECT_TRUE(wait_for([&] { return latest.submaps.submaps.size() == submap_count; }, 10.0))
      << latest.submaps.submaps.size() << " submaps after loading, " << submap_count << " saved";
  {
    std::lock_guard<std::mutex> lock(latest.mutex);
    latest.combined_mesh = visualization_msgs::Marker();
  }
  ASSERT_TRUE(call_trigger("generate_mesh", &message)) << message;
  EXPECT_TRUE(wait_for([] { return latest.combined_mesh.points.size() > 300; }, 10.0));
  EXPECT_TRUE(call_trigger("optimize_pose_graph", &message)) << message;

  operator_goes_on(node, &s4, folder_, submap_count);
}

// Start-up checks: a bad parameter stops covoxslam_node with a message naming it.
std::string run_and_capture(const std::string& command, int* status) {
  std::string output;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) {
    *status = -1;
    return output;
  }
  char buffer[512];
  while (std::fgets(buffer, sizeof(buffer), pipe)) output += buffer;
  *status = ::pclose(pipe);
  return output;
}

TEST(CovoxSlamNodeStartup, BadParametersStopTheNodeWithTheirName) {
  if (odometry_as_topic() || depth_images())
    GTEST_SKIP() << "checked once, in covoxslam_nodelet.test";
  const struct {
    const char* argument;
    const char* name;
  } cases[] = {{"_map/voxel_size_m:=-0.2", "map.voxel_size_m"},
               {"_submaps/policy:=sometimes", "submaps.policy"},
               {"_ros/tf_wait_timeout_s:=-1.0", "ros.tf_wait_timeout_s"},
               {"_ros/T_base_sensor:=[1.0,2.0,3.0]", "ros.T_base_sensor"},
               {"_tsdf/truncation_distance_m:=0.05", "truncation_distance_m"}};
  int index = 0;
  for (const auto& bad : cases) {
    int status = 0;
    // A fresh node name each time, so the parameters do not mix.
    const std::string output =
        run_and_capture(std::string(COVOXSLAM_NODE_PATH) + " __name:=bad_parameters_" +
                            std::to_string(index++) + " " + bad.argument,
                        &status);
    EXPECT_NE(status, 0) << bad.argument << ": the node did not fail:\n" << output;
    EXPECT_NE(output.find(std::string("parameter")), std::string::npos) << output;
    EXPECT_NE(output.find(bad.name), std::string::npos) << bad.argument << ":\n" << output;
  }
}

// The node reads configuration files with the offline runner's reader: a quoted number and an
// exponent (which `rosparam load` keeps as texts) are read in both, and a bad value stops both
// with the same message (tools_command_line_test.cpp checks the runner's side).
TEST(CovoxSlamNodeStartup, ConfigurationFilesReadAsTheOfflineRunnerReadsThem) {
  if (odometry_as_topic() || depth_images())
    GTEST_SKIP() << "checked once, in covoxslam_nodelet.test";
  const fs::path folder =
      fs::temp_directory_path() / ("covoxslam_yaml_" + std::to_string(::getpid()));
  fs::create_directories(folder);
  std::ofstream(folder / "good.yaml") << "map:\n  voxel_size_m: \"0.25\"\ntsdf:\n"
                                      << "  truncation_distance_m: 75e-2\n";
  std::ofstream(folder / "bad.yaml") << "map:\n  voxel_size_m: 0.2x\n";
  int status = 0;
  // `timeout` ends the node once it has started; its stdout is line-buffered for the check.
  std::string output =
      run_and_capture("timeout -k 10 6 stdbuf -oL " + std::string(COVOXSLAM_NODE_PATH) +
                          " __name:=yaml_good _config_file:=" + (folder / "good.yaml").string(),
                      &status);
  EXPECT_NE(output.find("voxel 0.25 m"), std::string::npos) << output;
  output = run_and_capture(std::string(COVOXSLAM_NODE_PATH) +
                               " __name:=yaml_bad _config_file:=" + (folder / "bad.yaml").string(),
                           &status);
  EXPECT_NE(status, 0) << output;
  EXPECT_NE(output.find("bad.yaml:2: parameter 'map.voxel_size_m': expected a finite decimal "
                        "number, got '0.2x'"),
            std::string::npos)
      << output;
  fs::remove_all(folder);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "covoxslam_rostest");
  ros::NodeHandle node;
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  spinner.stop();
  ros::shutdown();
  return result;
}

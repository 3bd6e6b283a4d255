#pragma once
// The synthetic scene the rostest node maps (covoxslam_rostest_node.cpp), shared with the
// planner checks (planner_rostest.cpp): a room with a pillar, whose distance is known exactly, a
// bag of a LiDAR flying through it, and calls of the node's services.
#include <filesystem>
#include <string>

#include <Eigen/Core>

namespace covox_rostest {

namespace fs = std::filesystem;

// An axis-aligned room (the sensor is inside) and a pillar (the sensor is outside).
inline const Eigen::Vector3d kRoomMin(-6.0, -5.0, 0.0), kRoomMax(6.0, 5.0, 3.0);
inline const Eigen::Vector3d kPillarMin(1.0, 1.0, 0.0), kPillarMax(2.0, 2.0, 3.0);
constexpr double kStart_s = 100.0;  // bag time of the first message
constexpr int kClouds = 12;         // valid clouds, at 2 Hz
constexpr double kCloudPeriod_s = 0.5;

// Distance from a point inside the room (outside the pillar) to the nearest surface.
double scene_distance(const Eigen::Vector3d& p);

// Writes a bag of `clouds` valid clouds from `start_s` on the flight path (a later start
// continues the flight), with /tf odometry and the /tf_static extrinsic, and the first bag's bad
// clouds (one without z, one in an unknown frame) when `bad_clouds`.
void write_bag(const std::string& path, double start_s = kStart_s, int clouds = kClouds,
               bool bad_clouds = true);

// Plays `bag_path` into the nodelet with the clock; returns rosbag's exit status, `log` receives
// what it said.
int play_bag(const fs::path& folder, const std::string& bag_path, std::string* log);

// /covoxslam/<name>.
std::string ns(const std::string& name);
// Calls a std_srvs/Trigger or covoxslam/FilePath service of the node; false when the call failed
// or was answered with success false (`message` says why).
bool call_trigger(const std::string& name, std::string* message);
bool call_file(const std::string& name, const std::string& path, std::string* message,
               bool overwrite = false);

}  // namespace covox_rostest

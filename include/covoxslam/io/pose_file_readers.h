#pragma once
// Readers for the reference-pose files of the shared datasets. Every pose goes through
// make_rigid_pose (rigid_pose_check.h): slightly-off rotations are repaired and counted in
// `stats`, impossible ones throw covox::Error naming the file and line.
#include <Eigen/Geometry>

#include <string>
#include <vector>

#include "covoxslam/io/rigid_pose_check.h"
#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {

// 7-Scenes / 3DMatch `frame-NNNNNN.pose.txt`: one 4x4 camera-to-world matrix (T_world_camera),
// four rows of four numbers.
Eigen::Isometry3d read_matrix4_pose_file(const std::string& path, ReadStats* stats = nullptr,
                                         const PoseTolerances& tolerances = PoseTolerances());

// Replica `traj.txt`: one row-major 4x4 camera-to-world matrix (16 numbers) per line.
std::vector<Eigen::Isometry3d> read_matrix4_per_line_trajectory(
    const std::string& path, ReadStats* stats = nullptr,
    const PoseTolerances& tolerances = PoseTolerances());

// KITTI odometry format (MulRan `odom_poses.txt` / `optimized_poses.txt`): the top 3 rows of a
// row-major 4x4 sensor-to-world matrix (12 numbers) per line.
std::vector<Eigen::Isometry3d> read_kitti_pose_file(
    const std::string& path, ReadStats* stats = nullptr,
    const PoseTolerances& tolerances = PoseTolerances());

// A named keyframe pose of a pose-graph dump.
struct KeyframePose {
  int id = 0;  // N of the "vN" label
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
};

// gtsam_points keyframe dump `graph.txt` (kitti_07_dump): `vN x y z qx qy qz qw` per line,
// sensor-to-world.
std::vector<KeyframePose> read_keyframe_graph_file(
    const std::string& path, ReadStats* stats = nullptr,
    const PoseTolerances& tolerances = PoseTolerances());

}  // namespace io
}  // namespace covox

#pragma once
// A small simulated scene for the SLAM pipeline tests: a walled yard with pillars and crates (so
// that overlapping submaps constrain x, y, z and yaw), a LiDAR flying a circle in it, and
// odometry that drifts in the four unobservable degrees of freedom. Sized for 2 CPU cores:
// 0.2 m voxels, 8-voxel blocks, a 192 x 16 beam LiDAR.
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <vector>

#include "covoxslam/pipeline/slam_system.h"
#include "support/small_slam_config.h"
#include "sim/sim_lidar.h"
#include "sim/sim_world.h"

namespace covox {
namespace pipeline {
namespace test_scene {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;

inline Eigen::Isometry3d pose_4dof(double x, double y, double z, double yaw_rad) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(x, y, z);
  return pose;
}

// 26 x 26 m yard, 3 m walls, ground at z = 0, and objects placed without symmetry.
inline sim::World make_yard() {
  sim::World world;
  sim::Plane ground;
  ground.mesh_half_size_m = 20.0;
  world.add(ground);
  auto wall = [&](double cx, double cy, double hx, double hy) {
    sim::Box box;
    box.centre_m = Eigen::Vector3d(cx, cy, 1.5);
    box.half_extent_m = Eigen::Vector3d(hx, hy, 1.5);
    world.add(box);
  };
  wall(0.0, 13.0, 13.0, 0.3);
  wall(0.0, -13.0, 13.0, 0.3);
  wall(13.0, 0.0, 0.3, 13.0);
  wall(-13.0, 0.0, 0.3, 13.0);
  const double pillars[][3] = {{3.0, 2.0, 0.4},   {-4.0, 5.0, 0.6}, {8.5, -7.0, 0.5},
                               {-9.0, -3.5, 0.3}, {1.0, -9.5, 0.7}, {6.0, 9.0, 0.35},
                               {-2.5, -2.0, 0.25}};
  for (const auto& p : pillars) {
    sim::Cylinder cylinder;
    cylinder.base_centre_m = Eigen::Vector3d(p[0], p[1], 0.0);
    cylinder.radius_m = p[2];
    cylinder.height_m = 2.5 + p[2];
    world.add(cylinder);
  }
  const double crates[][6] = {{-7.0, 8.0, 0.8, 1.2, 0.6, 0.5},  {9.5, 3.0, 0.5, 0.7, 1.5, 0.5},
                              {-1.0, 10.0, 1.0, 0.5, 1.0, 1.1}, {4.5, -4.0, 0.6, 0.6, 0.4, 0.3},
                              {-10.5, 9.5, 1.2, 1.0, 1.2, 0.0}, {-6.0, -9.0, 0.7, 1.5, 0.7, 0.8}};
  for (const auto& c : crates) {
    sim::Box box;
    box.centre_m = Eigen::Vector3d(c[0], c[1], c[2]);
    box.half_extent_m = Eigen::Vector3d(c[3], c[4], c[2]);
    box.rotation = Eigen::AngleAxisd(c[5], Eigen::Vector3d::UnitZ()).toRotationMatrix();
    world.add(box);
  }
  world.build();
  return world;
}

inline sim::LidarConfig small_lidar() {
  sim::LidarConfig lidar;
  lidar.columns = 192;
  lidar.rows = 16;
  lidar.vertical_fov_deg = 40.0;
  lidar.max_range_m = 20.0;
  lidar.range_noise_m = 0.01;
  lidar.dropout_probability = 0.0;
  return lidar;
}

// The true sensor pose on a circle of `radius_m` about the yard's centre, heading along the path.
inline Eigen::Isometry3d circle_pose(double t_s, double radius_m = 6.0, double speed_m_per_s = 1.0,
                                     double height_m = 1.5) {
  const double angle = speed_m_per_s * t_s / radius_m;
  return pose_4dof(radius_m * std::cos(angle), radius_m * std::sin(angle), height_m,
                   angle + 0.5 * kPi);
}

// Odometry drift as a slowly growing 4-DoF transform of the world: T_odom_sensor(t) =
// D(t) * T_world_sensor(t), D(t) = (Rz(yaw_rate t), bias t). D(0) = identity, so the first
// submap (the graph's fixed vertex) starts at the truth.
struct Drift {
  double yaw_rate_rad_per_s = 0.0;
  Eigen::Vector3d bias_m_per_s = Eigen::Vector3d::Zero();
  Eigen::Isometry3d at(double t_s) const {
    return pose_4dof(bias_m_per_s.x() * t_s, bias_m_per_s.y() * t_s, bias_m_per_s.z() * t_s,
                     yaw_rate_rad_per_s * t_s);
  }
};

inline SlamConfig yard_config() {
  SlamConfig config;
  config.device = Device::kCpu;
  config.map.voxel_size_m = 0.2f;
  config.map.voxels_per_side = 8;
  config.tsdf.truncation_distance_m = 0.6f;
  config.tsdf.max_ray_length_m = 20.0f;
  config.tsdf.use_const_weight = true;
  config.tsdf.use_sparsity_compensation_factor = true;
  config.tsdf.sparsity_compensation_factor = 20.0f;
  config.esdf.esdf_max_distance_m = 2.0f;
  config.submaps.policy = SubmapCreationPolicy::kTimeInterval;
  config.submaps.interval_s = 4.0;
  config.sensor_queue_size = 10000;
  config.submap_queue_size = 1000;
  testing_support::use_one_way_registration(&config);
  // The trust settings these mechanism tests were written against (the library's defaults before
  // the one configuration): fixed odometry sigmas, no floor, no gate, no residual test, no
  // verification, plain least squares. With the shipped ones the yard's lap ends 0.72 m RMS off.
  config.odometry_translation_sigma_vox = 0.5;  // 0.1 m
  config.odometry_yaw_sigma_rad = 0.01;
  config.odometry_drift_m_per_m = 0.0;
  config.odometry_drift_deg_per_m = 0.0;
  config.estimate_odometry_noise = false;
  config.registration_loss_scale_sigmas = 0.0;
  config.registration.information.min_sigma_vox = 0.0;
  config.registration.information.min_sigma_yaw_rad = 0.0;
  config.registration.gate.max_residual_vox = 0.0;
  config.registration.acceptance.max_residual_rms_vox = 0.0;
  config.registration.verification.max_mahalanobis_sq = 0.0;
  return config;
}

struct SimulatedScan {
  Scan scan;
  Eigen::Isometry3d T_world_sensor;  // the truth
};

inline SimulatedScan simulate(const sim::World& world, const sim::LidarConfig& lidar,
                              double stamp_s, const Eigen::Isometry3d& T_world_sensor,
                              const Eigen::Isometry3d& T_odom_world, uint64_t seed) {
  SimulatedScan out;
  out.T_world_sensor = T_world_sensor;
  out.scan.stamp_s = stamp_s;
  out.scan.T_odom_sensor = T_odom_world * T_world_sensor;
  out.scan.points_sensor_m = sim::simulate_scan(world, lidar, T_world_sensor, seed);
  return out;
}

// Root mean square of the position errors of poses against the truth, matched by index.
inline double position_rmse_m(const std::vector<Eigen::Isometry3d>& estimate,
                              const std::vector<Eigen::Isometry3d>& truth) {
  double sum = 0.0;
  for (size_t k = 0; k < truth.size(); ++k) {
    sum += (estimate[k].translation() - truth[k].translation()).squaredNorm();
  }
  return truth.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(truth.size()));
}

}  // namespace test_scene
}  // namespace pipeline
}  // namespace covox

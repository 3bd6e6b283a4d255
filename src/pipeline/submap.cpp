#include "covoxslam/pipeline/submap.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/map_integrators.h"

namespace covox {
namespace pipeline {

namespace {

using Clock = std::chrono::steady_clock;

double wrap_to_pi(double angle) {
  // atan2 of the angle's own sine and cosine: exact wrapping into (-pi, pi] for any input.
  return std::atan2(std::sin(angle), std::cos(angle));
}

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace

backend::Pose4Dof pose_4dof_from_isometry(const Eigen::Isometry3d& pose) {
  const Eigen::Matrix3d rotation = pose.linear();
  backend::Pose4Dof result;
  result.x = pose.translation().x();
  result.y = pose.translation().y();
  result.z = pose.translation().z();
  result.yaw = std::atan2(rotation(1, 0), rotation(0, 0));
  return result;
}

Eigen::Isometry3d to_isometry(const backend::Pose4Dof& pose) {
  Eigen::Isometry3d result = Eigen::Isometry3d::Identity();
  result.linear() = Eigen::AngleAxisd(pose.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  result.translation() = Eigen::Vector3d(pose.x, pose.y, pose.z);
  return result;
}

Eigen::Isometry3d gravity_aligned(const Eigen::Isometry3d& pose) {
  return to_isometry(pose_4dof_from_isometry(pose));
}

backend::Pose4Dof relative_pose_4dof(const backend::Pose4Dof& from, const backend::Pose4Dof& to) {
  // Must match FourDofModel::raw_residual, so that a graph built from odometry has zero cost.
  const double cs = std::cos(from.yaw), sn = std::sin(from.yaw);
  const double dx = to.x - from.x, dy = to.y - from.y;
  backend::Pose4Dof relative;
  relative.x = cs * dx + sn * dy;
  relative.y = -sn * dx + cs * dy;
  relative.z = to.z - from.z;
  relative.yaw = wrap_to_pi(to.yaw - from.yaw);
  return relative;
}

bool is_valid_rigid_pose(const Eigen::Isometry3d& pose) {
  if (!pose.matrix().allFinite()) return false;
  const Eigen::Matrix3d rotation = pose.linear();
  const double orthonormality_error =
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  return orthonormality_error < 1e-3 && rotation.determinant() > 0.0;
}

Eigen::Isometry3d blend_corrected_pose(const Eigen::Isometry3d& C_from,
                                       const Eigen::Isometry3d& C_to,
                                       const Eigen::Isometry3d& T_odom_sensor, double alpha) {
  const double a = std::min(1.0, std::max(0.0, alpha));
  const Eigen::Isometry3d from = C_from * T_odom_sensor;
  const Eigen::Isometry3d to = C_to * T_odom_sensor;
  if (a == 0.0) return from;
  if (a == 1.0) return to;
  // The rotation from `from` to `to`, a turn about z for yaw-only corrections.
  const Eigen::Matrix3d turn = to.linear() * from.linear().transpose();
  const double yaw = std::atan2(turn(1, 0), turn(0, 0));
  Eigen::Isometry3d result = Eigen::Isometry3d::Identity();
  result.linear() =
      Eigen::AngleAxisd(a * yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * from.linear();
  result.translation() = (1.0 - a) * from.translation() + a * to.translation();
  return result;
}

SubmapCreationPolicy parse_submap_creation_policy(const std::string& name) {
  if (name == "blocks") return SubmapCreationPolicy::kBlockCount;
  if (name == "time") return SubmapCreationPolicy::kTimeInterval;
  if (name == "distance") return SubmapCreationPolicy::kDistanceTravelled;
  throw Error("submap policy: unknown submap_creation_policy '" + name +
              "' (expected blocks, time or distance)");
}

const char* to_string(SubmapCreationPolicy policy) {
  switch (policy) {
    case SubmapCreationPolicy::kBlockCount:
      return "blocks";
    case SubmapCreationPolicy::kTimeInterval:
      return "time";
    case SubmapCreationPolicy::kDistanceTravelled:
      return "distance";
  }
  return "unknown";
}

void validate(const SubmapPolicyConfig& config) {
  switch (config.policy) {
    case SubmapCreationPolicy::kBlockCount:
      if (config.max_blocks < 1) {
        throw Error("submap policy: max_blocks must be at least 1, got " +
                    std::to_string(config.max_blocks));
      }
      break;
    case SubmapCreationPolicy::kTimeInterval:
      if (!(std::isfinite(config.interval_s) && config.interval_s > 0.0)) {
        throw Error("submap policy: interval_s must be a positive number of seconds, got " +
                    std::to_string(config.interval_s));
      }
      break;
    case SubmapCreationPolicy::kDistanceTravelled:
      if (!(std::isfinite(config.distance_m) && config.distance_m > 0.0)) {
        throw Error("submap policy: distance_m must be a positive number of metres, got " +
                    std::to_string(config.distance_m));
      }
      break;
  }
}

bool should_start_new_submap(const SubmapPolicyConfig& config, const SubmapStatistics& active,
                             double stamp_s, double step_m) {
  if (active.scans == 0) return false;
  switch (config.policy) {
    case SubmapCreationPolicy::kBlockCount:
      return active.blocks >= config.max_blocks;
    case SubmapCreationPolicy::kTimeInterval:
      return stamp_s - active.start_stamp_s >= config.interval_s;
    case SubmapCreationPolicy::kDistanceTravelled:
      return active.distance_travelled_m + step_m >= config.distance_m;
  }
  return false;
}

Submap::Submap(int64_t id, Device device, const map::TsdfMapConfig& map_config,
               const Eigen::Isometry3d& T_odom_submap)
    : id_(id),
      map_(device, map_config),
      odometry_pose_(pose_4dof_from_isometry(T_odom_submap)),
      pose_(odometry_pose_) {
  if (!is_valid_rigid_pose(T_odom_submap)) {
    throw Error("submap " + std::to_string(id) +
                ": the initial pose is not a finite rigid transform");
  }
}

integrators::IntegrationStats Submap::integrate(MapIntegrators& integrators,
                                                const integrators::PointCloudView& cloud,
                                                const Eigen::Isometry3d& T_odom_sensor,
                                                double stamp_s) {
  if (finished_) {
    throw Error("submap " + std::to_string(id_) +
                ": cannot integrate a scan into a finished submap");
  }
  const integrators::IntegrationStats stats =
      integrators.integrate(map_, cloud, submap_from_odometry(T_odom_sensor));
  const Eigen::Vector3d position_m = T_odom_sensor.translation();
  if (statistics_.scans == 0) {
    statistics_.start_stamp_s = stamp_s;
  } else {
    statistics_.distance_travelled_m += (position_m - last_position_odom_m_).norm();
  }
  last_position_odom_m_ = position_m;
  statistics_.end_stamp_s = stamp_s;
  ++statistics_.scans;
  statistics_.points_in += stats.points_in;
  statistics_.points_dropped += stats.dropped_total();
  statistics_.blocks = map_.block_count();
  return stats;
}

SubmapFinishTimes Submap::finish(MapIntegrators& integrators) {
  SubmapFinishTimes times;
  if (finished_) return times;

  // The whole ESDF at once: the submap will not change again, so incremental bookkeeping would
  // only cost time.
  auto start = Clock::now();
  integrators.update_esdf_all(map_);
  times.esdf_s = seconds_since(start);

  start = Clock::now();
  mesh_ = integrators.extract_mesh(map_);
  mesh_triangles_ = static_cast<int64_t>(mesh_.triangle_count());
  times.mesh_s = seconds_since(start);

  // The box of the allocated blocks: block b spans [b, b + 1) * block size on each axis.
  Buffer<Index3D> keys(map_.device());
  Buffer<uint32_t> slots(map_.device());
  map_.blocks().export_entries(&keys, &slots);
  const std::vector<Index3D> indices = keys.to_host(integrators.stream());
  bounding_box_submap_.setEmpty();
  const double block_m = map_.block_size_m();
  for (const Index3D& index : indices) {
    const Eigen::Vector3d corner(index.x * block_m, index.y * block_m, index.z * block_m);
    bounding_box_submap_.extend(corner);
    bounding_box_submap_.extend(corner + Eigen::Vector3d::Constant(block_m));
  }
  statistics_.blocks = map_.block_count();
  finished_ = true;
  return times;
}

Eigen::AlignedBox3d Submap::bounding_box_world() const {
  Eigen::AlignedBox3d box;
  if (bounding_box_submap_.isEmpty()) return box;
  const Eigen::Isometry3d T_world_submap = this->T_world_submap();
  for (int corner = 0; corner < 8; ++corner) {
    box.extend(T_world_submap *
               bounding_box_submap_.corner(static_cast<Eigen::AlignedBox3d::CornerType>(corner)));
  }
  return box;
}

}  // namespace pipeline
}  // namespace covox

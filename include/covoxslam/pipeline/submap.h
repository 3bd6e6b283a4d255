#pragma once
// Submap: one piece of the map, built by the frontend from consecutive scans and then frozen
// (paper III-F, voxgraph's submaps). It holds the map a Mapper owns (one TsdfMap: TSDF, colour and
// ESDF layers), its pose T_W_S, bounding box and statistics, and once finished its mesh; the
// integration stage that builds it (pipeline/map_integrators.h) is lent by each call, so scratch
// memory is per thread, not per submap. Its frame S is the gravity-aligned pose of its first
// scan's sensor in the odometry frame (4 DoF, docs/design.md "Submaps"); T_odom_S is fixed at
// creation, T_W_S (the corrected pose in the mission frame) starts equal to it and is updated by
// the backend. Not thread-safe: the frontend owns it while it is active, then hands it to the
// backend through the submap queue; SlamSystem guards the pose that both sides read.
#include <cstdint>
#include <string>
#include <utility>

#include <Eigen/Geometry>

#include "covoxslam/backend/pose_graph_types.h"
#include "covoxslam/core/device.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace pipeline {

class MapIntegrators;

// ---- 4-DoF pose helpers ------------------------------------------------------------------------

// Position and heading of a pose; the heading is the direction of its x axis projected onto the
// horizontal plane (well defined unless the x axis points straight up or down).
backend::Pose4Dof pose_4dof_from_isometry(const Eigen::Isometry3d& pose);
Eigen::Isometry3d to_isometry(const backend::Pose4Dof& pose);
// `pose` with its roll and pitch removed.
Eigen::Isometry3d gravity_aligned(const Eigen::Isometry3d& pose);
// The pose of `to` in the frame of `from`, in the convention of FourDofModel's relative
// constraint: (dx, dy) rotated into the heading of `from`, dz, and the wrapped yaw difference.
backend::Pose4Dof relative_pose_4dof(const backend::Pose4Dof& from, const backend::Pose4Dof& to);
// True when the translation and rotation are finite and the rotation is orthonormal (1e-3).
bool is_valid_rigid_pose(const Eigen::Isometry3d& pose);
// A pose between two corrections of the same odometry pose: A = C_from * T_odom_sensor and
// B = C_to * T_odom_sensor, where C_from and C_to differ by a yaw about z and a translation (as
// the corrections T_world_submap * T_odom_submap^-1 of gravity-aligned submaps do). The result
// lies a fraction `alpha` (clamped to [0, 1]) of the way from A to B: position
// (1 - alpha) A + alpha B, and A's rotation turned by alpha times the yaw from A to B (the
// shorter way round). alpha 0 gives A and 1 gives B exactly.
Eigen::Isometry3d blend_corrected_pose(const Eigen::Isometry3d& C_from,
                                       const Eigen::Isometry3d& C_to,
                                       const Eigen::Isometry3d& T_odom_sensor, double alpha);

// ---- Creation policy ---------------------------------------------------------------------------

enum class SubmapCreationPolicy {
  kBlockCount,         // the paper's: a new submap once the active one has max_blocks blocks
  kTimeInterval,       // voxgraph's: a new submap every interval_s seconds of sensor time
  kDistanceTravelled,  // a new submap every distance_m metres of sensor path
};
// "blocks", "time" or "distance"; throws covox::Error naming the bad value otherwise.
SubmapCreationPolicy parse_submap_creation_policy(const std::string& name);
const char* to_string(SubmapCreationPolicy policy);

struct SubmapPolicyConfig {
  SubmapCreationPolicy policy = SubmapCreationPolicy::kTimeInterval;
  double interval_s = 5.0;    // half voxgraph's default: half the odometry drift in a submap
  double distance_m = 10.0;   // sensor path length per submap
  int64_t max_blocks = 1000;  // allocated TSDF blocks per submap
};
// Throws covox::Error naming the first invalid parameter (only the chosen policy's one is checked).
void validate(const SubmapPolicyConfig& config);

struct SubmapStatistics {
  int64_t scans = 0;                  // scans integrated
  int64_t points_in = 0;              // points handed to the integrator
  int64_t points_dropped = 0;         // of those, dropped by it (non-finite, too close or far)
  int64_t blocks = 0;                 // allocated TSDF blocks
  double start_stamp_s = 0.0;         // first scan
  double end_stamp_s = 0.0;           // last scan
  double distance_travelled_m = 0.0;  // sensor path length from the first to the last scan
};

// Whether a scan stamped `stamp_s`, `step_m` metres from the active submap's last scan, starts a
// new submap rather than joining the active one. The decision is taken when the next scan
// arrives, so a submap covers [start, start + interval) in time or less than distance_m of path,
// and the block count reached by its last scan. An empty submap never ends.
bool should_start_new_submap(const SubmapPolicyConfig& config, const SubmapStatistics& active,
                             double stamp_s, double step_m);

// ---- The submap --------------------------------------------------------------------------------

// Wall time of finish()'s parts, for the per-module timing table.
struct SubmapFinishTimes {
  double esdf_s = 0.0;
  double mesh_s = 0.0;
};

class Submap {
 public:
  // `T_odom_submap` must be gravity aligned (see gravity_aligned()).
  Submap(int64_t id, Device device, const map::TsdfMapConfig& map_config,
         const Eigen::Isometry3d& T_odom_submap);

  int64_t id() const { return id_; }
  map::TsdfMap& map() { return map_; }
  const map::TsdfMap& map() const { return map_; }

  const backend::Pose4Dof& odometry_pose() const { return odometry_pose_; }
  Eigen::Isometry3d T_odom_submap() const { return to_isometry(odometry_pose_); }
  // Corrected pose T_W_S (starts as the odometry pose).
  const backend::Pose4Dof& pose() const { return pose_; }
  void set_pose(const backend::Pose4Dof& pose) { pose_ = pose; }
  Eigen::Isometry3d T_world_submap() const { return to_isometry(pose_); }

  const SubmapStatistics& statistics() const { return statistics_; }

  // Integrates a scan taken at odometry pose T_odom_sensor (device memory of the map's device)
  // with `integrators` at its pose in the submap frame, and updates the statistics. Returns when
  // the scan is in the map. Throws covox::Error after finish().
  integrators::IntegrationStats integrate(MapIntegrators& integrators,
                                          const integrators::PointCloudView& cloud,
                                          const Eigen::Isometry3d& T_odom_sensor, double stamp_s);
  // T_S_sensor for a scan at odometry pose T_odom_sensor.
  Eigen::Isometry3d submap_from_odometry(const Eigen::Isometry3d& T_odom_sensor) const {
    return T_odom_submap().inverse() * T_odom_sensor;
  }

  // Freezes the submap: computes the whole ESDF and the mesh with `integrators`, and the
  // bounding box. Idempotent.
  SubmapFinishTimes finish(MapIntegrators& integrators);
  bool finished() const { return finished_; }

  // Mesh in the submap frame (empty before finish() and after take_mesh()).
  const map::Mesh& mesh() const { return mesh_; }
  // Moves the mesh out (to the SubmapStore, which holds finished submaps' meshes); the triangle
  // count stays.
  map::Mesh take_mesh() { return std::move(mesh_); }
  // Triangles of the mesh finish() made, whoever holds it now.
  int64_t mesh_triangles() const { return mesh_triangles_; }
  // Axis-aligned box of the allocated blocks in the submap frame (empty before finish()).
  const Eigen::AlignedBox3d& bounding_box_submap() const { return bounding_box_submap_; }
  // The same box's corners moved by T_W_S, boxed again in the world frame.
  Eigen::AlignedBox3d bounding_box_world() const;

 private:
  int64_t id_;
  map::TsdfMap map_;
  backend::Pose4Dof odometry_pose_;
  backend::Pose4Dof pose_;
  SubmapStatistics statistics_;
  Eigen::Vector3d last_position_odom_m_ = Eigen::Vector3d::Zero();
  bool finished_ = false;
  map::Mesh mesh_;
  int64_t mesh_triangles_ = 0;
  Eigen::AlignedBox3d bounding_box_submap_;
};

}  // namespace pipeline
}  // namespace covox

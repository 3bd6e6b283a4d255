#pragma once
// The scene of the registration tests: a closed room (every face constrains x, y, z and yaw)
// scanned once per submap by a simulated LiDAR, each submap's frame at its sensor (voxgraph puts a
// submap's origin at the robot).
#include <Eigen/Geometry>

#include <memory>

#include "covoxslam/backend/pose_graph_types.h"
#include "covoxslam/backend/registration.h"
#include "covoxslam/core/device.h"
#include "covoxslam/map/tsdf_map.h"
#include "support/analytic_scene.h"

namespace covox {
namespace testing_support {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

// The rigid transform of a 4-DoF pose: yaw about z, then the translation.
Eigen::Isometry3d isometry_of(const backend::Pose4Dof& pose);

// A 6 x 5 x 3 m room, a few centimetres off the origin.
AnalyticScene registration_room();

// One submap with voxels of `voxel_size_m`: a single 720 x 64 beam scan of `room` from the sensor
// at T_W_S, integrated with the sensor at the submap's origin (truncation 0.3 m, 10 m rays), with
// its ESDF up to esdf_max_distance_m (1 m unless given).
std::unique_ptr<map::TsdfMap> scan_room_submap(Device device, const AnalyticScene& room,
                                               const backend::Pose4Dof& T_W_S, float voxel_size_m,
                                               float esdf_max_distance_m = 1.0f);

// Two scans of one scene as submaps j (sensor at the origin) and i (sensor at true_T_Sj_Si),
// each with its registration points (sampling ratio 0.25): the set-up of the pairwise and
// symmetric registration tests.
struct ScannedSubmapPair {
  std::unique_ptr<map::TsdfMap> map_i, map_j;
  std::unique_ptr<backend::RegistrationPoints> points_i, points_j;
  backend::Pose4Dof true_T_Sj_Si;

  // Both directions, for align_submaps_symmetric.
  backend::SymmetricRegistrationPair symmetric(double reverse_weight_scale = 1.0) const;
};
ScannedSubmapPair scan_submap_pair(Device device, const AnalyticScene& scene,
                                   const backend::Pose4Dof& true_T_Sj_Si, float voxel_size_m,
                                   float esdf_max_distance_m = 1.0f);

}  // namespace testing_support
}  // namespace covox

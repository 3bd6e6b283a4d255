#include "support/registration_room.h"

#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"

namespace covox {
namespace testing_support {

Eigen::Isometry3d isometry_of(const backend::Pose4Dof& pose) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(pose.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(pose.x, pose.y, pose.z);
  return t;
}

AnalyticScene registration_room() {
  AnalyticScene room;
  room.shape = Shape::kBox;
  room.center = Eigen::Vector3d(0.03, -0.02, 0.1);
  room.half_extent = Eigen::Vector3d(3.0, 2.5, 1.5);
  return room;
}

std::unique_ptr<map::TsdfMap> scan_room_submap(Device device, const AnalyticScene& room,
                                               const backend::Pose4Dof& T_W_S, float voxel_size_m,
                                               float esdf_max_distance_m) {
  auto map = std::make_unique<map::TsdfMap>(device, map::TsdfMapConfig{voxel_size_m, 8, {}});
  integrators::TsdfIntegratorConfig tsdf_config;
  tsdf_config.truncation_distance_m = 0.3f;
  tsdf_config.max_ray_length_m = 10.0f;
  // The scene is seen from the sensor's world pose; the points go into the submap's own frame.
  integrators::TsdfIntegrator(tsdf_config)
      .integrate(*map, simulate_lidar(room, isometry_of(T_W_S), 720, 64, 90.0, 9.5), {},
                 Eigen::Isometry3d::Identity());
  integrators::EsdfIntegratorConfig esdf_config;
  esdf_config.esdf_max_distance_m = esdf_max_distance_m;
  integrators::EsdfIntegrator(esdf_config).update_all(*map, Stream(device));
  return map;
}

ScannedSubmapPair scan_submap_pair(Device device, const AnalyticScene& scene,
                                   const backend::Pose4Dof& true_T_Sj_Si, float voxel_size_m,
                                   float esdf_max_distance_m) {
  ScannedSubmapPair pair;
  pair.true_T_Sj_Si = true_T_Sj_Si;
  pair.map_j =
      scan_room_submap(device, scene, backend::Pose4Dof{}, voxel_size_m, esdf_max_distance_m);
  pair.map_i = scan_room_submap(device, scene, true_T_Sj_Si, voxel_size_m, esdf_max_distance_m);
  backend::RegistrationPointsConfig config;
  config.sampling_ratio = 0.25f;
  const Stream stream(device);
  pair.points_i = std::make_unique<backend::RegistrationPoints>(
      extract_registration_points(*pair.map_i, config, stream));
  pair.points_j = std::make_unique<backend::RegistrationPoints>(
      extract_registration_points(*pair.map_j, config, stream));
  return pair;
}

backend::SymmetricRegistrationPair ScannedSubmapPair::symmetric(double reverse_weight_scale) const {
  backend::SymmetricRegistrationPair view;
  view.points_i = points_i.get();
  view.map_j = map_j.get();
  view.points_j = points_j.get();
  view.map_i = map_i.get();
  view.reverse_weight_scale = reverse_weight_scale;
  return view;
}

}  // namespace testing_support
}  // namespace covox

#include "support/small_slam_config.h"

namespace covox {
namespace testing_support {

void use_one_way_registration(pipeline::SlamConfig* config) {
  config->registration.alignment.symmetric = false;
  config->registration.alignment.coarse_levels = 0;
  config->registration.acceptance.max_correction_m = 2.0;
  config->registration.revisits.wall_search = false;
  config->registration.gate.worst_fraction = 0.0;
  config->interpolate_trajectory_correction = false;
}

pipeline::SlamConfig small_slam_config() {
  pipeline::SlamConfig config;
  config.device = Device::kCpu;
  config.map.voxel_size_m = 0.2f;
  config.map.voxels_per_side = 8;
  config.tsdf.truncation_distance_m = 0.6f;
  config.tsdf.max_ray_length_m = 8.0f;
  config.esdf.esdf_max_distance_m = 1.0f;
  config.submaps.policy = pipeline::SubmapCreationPolicy::kTimeInterval;
  config.submaps.interval_s = 1.0;
  config.sensor_queue_size = 1000;
  config.submap_queue_size = 100;
  use_one_way_registration(&config);
  return config;
}

}  // namespace testing_support
}  // namespace covox

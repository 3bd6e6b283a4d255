#pragma once
// A spinning multi-beam LiDAR in the manner of the Ouster OS1-64: `rows` beams spread evenly over
// the vertical field of view, `columns` firings per revolution. Every beam is cast into the world
// at once from the scan pose (the ARCHE reference pipeline motion-undistorts its clouds, so an
// instantaneous scan is what the mapping sees). Returns outside [min_range, max_range] and dropped
// beams give no point; kept ranges get Gaussian noise along the beam.
#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/vec3.h"
#include "sim_world.h"

namespace covox {
namespace sim {

struct LidarConfig {
  int columns = 1024;  // horizontal resolution; 512 or 256 keep CPU runs fast
  int rows = 64;
  double vertical_fov_deg = 33.2;  // OS1-64: +-16.6 degrees
  double min_range_m = 0.3;
  double max_range_m = 120.0;
  double range_noise_m = 0.02;        // standard deviation along the beam
  double dropout_probability = 0.01;  // per beam, independent of the hit
};

// Throws covox::Error naming the first invalid parameter.
void validate(const LidarConfig& config);

// Unit direction of beam (row, column) in the sensor frame (x forward, z up); row 0 is the lowest.
Eigen::Vector3d beam_direction(const LidarConfig& config, int row, int column);

// The points (sensor frame) of one scan at T_world_sensor. `scan_seed` selects the noise and
// dropouts: the same seed gives the same points, whatever the thread count.
std::vector<Vec3f> simulate_scan(const World& world, const LidarConfig& config,
                                 const Eigen::Isometry3d& T_world_sensor, uint64_t scan_seed);

}  // namespace sim
}  // namespace covox

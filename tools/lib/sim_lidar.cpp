#include "sim_lidar.h"

#include <cmath>

#include "covoxslam/core/error.h"
#include "sim_random.h"

namespace covox {
namespace sim {

void validate(const LidarConfig& config) {
  const auto fail = [](const std::string& what) { throw Error("LiDAR model: " + what); };
  if (config.columns <= 0 || config.rows <= 0) fail("columns and rows must be positive");
  if (!(config.vertical_fov_deg > 0.0 && config.vertical_fov_deg < 180.0))
    fail("vertical_fov_deg must be in (0, 180)");
  if (!(config.min_range_m >= 0.0 && config.max_range_m > config.min_range_m))
    fail("need 0 <= min_range_m < max_range_m");
  if (!(config.range_noise_m >= 0.0)) fail("range_noise_m must not be negative");
  if (!(config.dropout_probability >= 0.0 && config.dropout_probability <= 1.0))
    fail("dropout_probability must be in [0, 1]");
}

Eigen::Vector3d beam_direction(const LidarConfig& config, int row, int column) {
  const double pi = 3.14159265358979323846;
  // Beams at both ends of the field of view (the OS1 spreads its 64 beams over it inclusively).
  const double fraction = config.rows > 1 ? static_cast<double>(row) / (config.rows - 1) : 0.5;
  const double elevation = (fraction - 0.5) * config.vertical_fov_deg * pi / 180.0;
  const double azimuth = 2.0 * pi * column / config.columns;
  return Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                         std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
}

std::vector<Vec3f> simulate_scan(const World& world, const LidarConfig& config,
                                 const Eigen::Isometry3d& T_world_sensor, uint64_t scan_seed) {
  validate(config);
  const int beams = config.rows * config.columns;
  // One slot per beam so threads never contend; compacted in beam order afterwards, which keeps
  // the output independent of scheduling.
  std::vector<float> ranges(beams, 0.0f);
  const Eigen::Vector3d origin = T_world_sensor.translation();
  const Eigen::Matrix3d rotation = T_world_sensor.linear();
#pragma omp parallel for schedule(dynamic, 8)
  for (int row = 0; row < config.rows; ++row) {
    for (int column = 0; column < config.columns; ++column) {
      const int beam = row * config.columns + column;
      const Eigen::Vector3d direction = rotation * beam_direction(config, row, column);
      const double range = world.intersect(origin, direction, config.max_range_m);
      if (!(range >= config.min_range_m && range <= config.max_range_m)) continue;
      Random random(stream_seed(scan_seed, static_cast<uint64_t>(beam)));
      if (config.dropout_probability > 0.0 && random.uniform() < config.dropout_probability)
        continue;
      const double noisy =
          config.range_noise_m > 0.0 ? range + config.range_noise_m * random.normal() : range;
      if (noisy > 0.0) ranges[beam] = static_cast<float>(noisy);
    }
  }
  std::vector<Vec3f> points;
  points.reserve(beams);
  for (int row = 0; row < config.rows; ++row) {
    for (int column = 0; column < config.columns; ++column) {
      const float range = ranges[row * config.columns + column];
      if (range <= 0.0f) continue;
      const Eigen::Vector3d p = beam_direction(config, row, column) * static_cast<double>(range);
      points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()),
                          static_cast<float>(p.z()));
    }
  }
  return points;
}

}  // namespace sim
}  // namespace covox

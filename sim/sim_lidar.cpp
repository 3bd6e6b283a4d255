#include "sim/sim_lidar.h"

#include <cmath>
#include <string>

#include "covoxslam/core/error.h"
#include "sim/sim_random.h"

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

uint32_t column_time_ns(const LidarConfig& config, double sweep_period_s, int column) {
  return static_cast<uint32_t>(
      std::llround(1e9 * sweep_period_s * static_cast<double>(column) / config.columns));
}

namespace {

// The noisy range of every beam (0: no return), one slot per beam so that threads never contend.
// Column c is cast from column_poses[c], or from column_poses[0] when there is only one.
std::vector<float> cast_ranges(const World& world, const LidarConfig& config,
                               const std::vector<Eigen::Isometry3d>& column_poses,
                               uint64_t scan_seed) {
  const int beams = config.rows * config.columns;
  std::vector<float> ranges(beams, 0.0f);
  const bool one_pose = column_poses.size() == 1;
#pragma omp parallel for schedule(dynamic, 8)
  for (int row = 0; row < config.rows; ++row) {
    for (int column = 0; column < config.columns; ++column) {
      const int beam = row * config.columns + column;
      const Eigen::Isometry3d& pose = column_poses[one_pose ? 0 : column];
      const Eigen::Vector3d direction = pose.linear() * beam_direction(config, row, column);
      const double range = world.intersect(pose.translation(), direction, config.max_range_m);
      if (!(range >= config.min_range_m && range <= config.max_range_m)) continue;
      Random random(stream_seed(scan_seed, static_cast<uint64_t>(beam)));
      if (config.dropout_probability > 0.0 && random.uniform() < config.dropout_probability)
        continue;
      const double noisy =
          config.range_noise_m > 0.0 ? range + config.range_noise_m * random.normal() : range;
      if (noisy > 0.0) ranges[beam] = static_cast<float>(noisy);
    }
  }
  return ranges;
}

// The returns in beam order (which keeps the output independent of scheduling), each along its
// beam in the sensor frame of its column, with its column's time when `column_times_ns` is given.
SweepScan compact(const LidarConfig& config, const std::vector<float>& ranges,
                  const std::vector<uint32_t>& column_times_ns) {
  SweepScan scan;
  scan.points_sensor_m.reserve(ranges.size());
  if (!column_times_ns.empty()) scan.times_ns.reserve(ranges.size());
  for (int row = 0; row < config.rows; ++row) {
    for (int column = 0; column < config.columns; ++column) {
      const float range = ranges[row * config.columns + column];
      if (range <= 0.0f) continue;
      const Eigen::Vector3d p = beam_direction(config, row, column) * static_cast<double>(range);
      scan.points_sensor_m.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()),
                                        static_cast<float>(p.z()));
      if (!column_times_ns.empty()) scan.times_ns.push_back(column_times_ns[column]);
    }
  }
  return scan;
}

}  // namespace

SweepScan simulate_sweep(const World& world, const LidarConfig& config,
                         const PoseAtTime& T_world_sensor_at, double sweep_period_s,
                         uint64_t scan_seed) {
  validate(config);
  if (config.instantaneous) {
    return compact(config, cast_ranges(world, config, {T_world_sensor_at(0.0)}, scan_seed), {});
  }
  if (!(sweep_period_s > 0.0 && sweep_period_s < 4.0)) {
    throw Error("LiDAR model: the sweep period must be in (0, 4) s, got " +
                std::to_string(sweep_period_s));
  }
  std::vector<uint32_t> column_times_ns(config.columns);
  std::vector<Eigen::Isometry3d> column_poses(config.columns);
  for (int column = 0; column < config.columns; ++column) {
    column_times_ns[column] = column_time_ns(config, sweep_period_s, column);
    // Cast at the recorded time itself, so that a point and its time agree to the nanosecond.
    column_poses[column] = T_world_sensor_at(static_cast<double>(column_times_ns[column]) * 1e-9);
  }
  return compact(config, cast_ranges(world, config, column_poses, scan_seed), column_times_ns);
}

std::vector<Vec3f> simulate_scan(const World& world, const LidarConfig& config,
                                 const Eigen::Isometry3d& T_world_sensor, uint64_t scan_seed) {
  validate(config);
  return compact(config, cast_ranges(world, config, {T_world_sensor}, scan_seed), {})
      .points_sensor_m;
}

}  // namespace sim
}  // namespace covox

#pragma once
// A spinning multi-beam LiDAR in the manner of the Ouster OS1-64: `rows` beams spread evenly over
// the vertical field of view, `columns` firings per revolution. As the real sensor does, it fires
// its columns one after the other over a sweep (one revolution at the scan rate): column c fires
// at c / columns of the sweep period after the scan's start (the cloud's stamp), its ray is cast
// from the sensor pose at that time, and its points are given in the sensor frame at that time,
// with the time as nanoseconds after the scan's start (the Ouster driver's per-point field `t`).
// A sensor moving during the sweep thus gives a distorted cloud, which mapping must de-skew.
// `instantaneous` casts every beam at once from the pose at the scan's start instead (no times):
// a motion-undistorted cloud such as the ARCHE reference pipeline's.
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/vec3.h"
#include "sim/sim_world.h"

namespace covox {
namespace sim {

// Returns outside [min_range, max_range] and dropped beams give no point; kept ranges get
// Gaussian noise along the beam; a beam's noise and dropout are the same whether the scan is
// distorted or not.
struct LidarConfig {
  int columns = 1024;  // horizontal resolution; 512 or 256 keep CPU runs fast
  int rows = 64;
  double vertical_fov_deg = 33.2;  // OS1-64: +-16.6 degrees
  double min_range_m = 0.3;
  double max_range_m = 120.0;
  double range_noise_m = 0.02;        // standard deviation along the beam
  double dropout_probability = 0.01;  // per beam, independent of the hit
  bool instantaneous = false;         // every column at the scan's start (no distortion)
};

// Throws covox::Error naming the first invalid parameter.
void validate(const LidarConfig& config);

// Unit direction of beam (row, column) in the sensor frame (x forward, z up); row 0 is the lowest.
Eigen::Vector3d beam_direction(const LidarConfig& config, int row, int column);

// Nanoseconds after the scan's start at which `column` fires: column / columns of the sweep,
// rounded to the nanosecond. Increases with the column, in [0, sweep period).
uint32_t column_time_ns(const LidarConfig& config, double sweep_period_s, int column);

// A per-point time of the cloud (nanoseconds after the scan's start) in seconds, as a float:
// what SourceScan::point_times_s holds.
inline float point_time_s(uint32_t time_ns) {
  return static_cast<float>(static_cast<double>(time_ns) * 1e-9);
}

// One scan: points in beam order (row by row, each row by column), each in the sensor frame at its
// column's firing time, and those times (nanoseconds after the scan's start; empty for an
// instantaneous scan).
struct SweepScan {
  std::vector<Vec3f> points_sensor_m;
  std::vector<uint32_t> times_ns;
};

// The pose T_world_sensor at a time given in seconds after the scan's start.
using PoseAtTime = std::function<Eigen::Isometry3d(double seconds_after_start)>;

// One scan over a sweep of `sweep_period_s` along `T_world_sensor_at` (asked once per column, in
// column order, from the calling thread). `scan_seed` selects the noise and dropouts: the same
// seed gives the same points, whatever the thread count.
SweepScan simulate_sweep(const World& world, const LidarConfig& config,
                         const PoseAtTime& T_world_sensor_at, double sweep_period_s,
                         uint64_t scan_seed);

// The points (sensor frame) of one instantaneous scan at T_world_sensor, whatever
// config.instantaneous says (the same points as simulate_sweep with a constant pose).
std::vector<Vec3f> simulate_scan(const World& world, const LidarConfig& config,
                                 const Eigen::Isometry3d& T_world_sensor, uint64_t scan_seed);

}  // namespace sim
}  // namespace covox

#pragma once
// The simulated flight: the figure-8 path (Figure8Path, flown as laps with per-lap offsets), the
// ground-truth pose as a function of time (truth_pose_at), and the drifting odometry
// (simulate_odometry, odometry_at: random walks with biases in x, y, z and yaw, the four degrees
// of freedom visual-inertial odometry cannot observe). docs/design.md ("Tools, modules and
// tests") has the path's shape, the laps and the drift model.
#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/io/trajectory_io.h"

namespace covox {
namespace sim {

struct FlightConfig {
  double path_length_m = 400.0;  // the whole flight, all laps
  // One lap of the figure 8; 0: the path length split into the fewest whole laps of at most 9 A
  // (A: the lobe half length below), so a longer flight repeats a figure 8 of the default's size.
  double lap_length_m = 0.0;
  double speed_m_per_s = 2.0;
  double scan_rate_hz = 10.0;
  // Odometry poses a second (the bag's tf odom -> imu); a whole multiple of the scan rate.
  double odometry_rate_hz = 100.0;
  // The yaw sweep on top of the direction of travel; amplitude 0 flies facing forward.
  double yaw_sweep_amplitude_deg = 30.0;
  double yaw_sweep_period_s = 4.0;
  double lobe_half_length_m =
      55.0;  // A: the figure 8 spans x in [-A, A]; B follows from the length
  double cruise_altitude_m = 3.5;
  double indoor_altitude_m = 1.6;
  // The altitude is indoor within this horizontal distance of the passage centre, cruise beyond
  // it plus the transition length.
  double indoor_radius_m = 10.0;
  double altitude_transition_m = 12.0;
  double start_time_s = 1000.0;
  // Per-lap offsets from the second lap on: uniform in [-max, max], a quarter of it at the
  // passage.
  double lap_lateral_offset_m = 1.0;
  double lap_altitude_offset_m = 0.5;
  double lap_blend_length_m = 40.0;  // offsets change over this much of a lap's start
  uint64_t variation_seed = 1;
};

// Odometry = truth + drift: a yaw error that grows as a random walk with a bias rotates every
// later displacement, and the position picks up its own random walk with a bias. The drift is
// drawn at the scan rate and interpolated between the samples (odometry_at), so the odometry
// exists at any time, as a visual-inertial odometry's high-rate output does.
struct DriftConfig {
  Eigen::Vector3d bias_velocity_m_per_s = Eigen::Vector3d(0.008, -0.006, 0.0015);
  double yaw_bias_deg_per_s = 0.015;
  double translation_random_walk_m_per_sqrt_s = 0.01;
  double yaw_random_walk_deg_per_sqrt_s = 0.03;
  // If the odometry ends closer than this to the truth, the whole drift (biases and random walks
  // alike) is scaled up until it does not: the default flight has at least this much drift.
  double min_final_drift_m = 3.0;
  // > 0: instead of at least min_final_drift_m, the whole drift is scaled so that the odometry
  // ends this percentage of the distance flown from the truth (odometry is commonly rated by its
  // drift per distance travelled).
  double final_drift_percent = 0.0;

  // Every rate (biases and random walks) multiplied by `factor` >= 0; factor 0 also drops the
  // least final drift and the drift percentage, so the odometry equals the truth
  // (simulate_flight --drift-scale 0: the mapping's own error without drift to correct).
  DriftConfig scaled(double factor) const;
};

struct StampedIsometry {
  double stamp_s = 0.0;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // T_world_sensor
};

// A lemniscate of Gerono, x = A sin(theta), y = B sin(theta) cos(theta), starting at the crossing
// point; its +x lobe end, nearly straight there (curvature radius B^2 / A), runs through the
// passage building, around which the altitude drops from cruise to indoor height. Laps after the
// first carry their own offsets (deterministic from `variation_seed`); distances along the flight
// are those of the nominal figure 8, so on a shifted lap the speed varies by the offset over the
// turn radius (up to about 11 % in the tightest turn).
class Figure8Path {
 public:
  // Throws covox::Error when a lap length cannot be reached with the lobe half length (it must be
  // more than about 4.1 A and less than about 13 A).
  explicit Figure8Path(const FlightConfig& config);

  double length_m() const { return length_m_; }  // the whole flight
  double lap_length_m() const { return arc_length_.back(); }
  size_t lap_count() const { return lap_count_; }  // the last one may be partial
  double lobe_half_length_m() const { return a_; }
  double lobe_width_m() const { return b_; }
  // The point where the path crosses y = 0 at the +x lobe end, and the x of the path at `y_m`
  // near there (|y_m| < B / 2): where the passage building's doors go.
  Eigen::Vector2d passage_centre_m() const { return Eigen::Vector2d(a_, 0.0); }
  double passage_x_at_m(double y_m) const;

  // Horizontal position and unit direction of travel after `distance_m` along the path.
  Eigen::Vector2d position_m(double distance_m) const;
  Eigen::Vector2d direction(double distance_m) const;
  double altitude_m(double distance_m) const;

 private:
  struct LapOffset {
    double lateral_m = 0.0, altitude_m = 0.0;
  };
  // The lap that `distance_m` falls in and the distance into that lap.
  size_t lap_at(double distance_m, double* into_lap_m) const;
  // The offsets at `distance_m`, blended between the previous lap's and this lap's, and scaled
  // down near the passage.
  LapOffset offset_at(double distance_m) const;
  double indoor_blend(const Eigen::Vector2d& nominal_m) const;
  double theta_at(double lap_distance_m) const;
  Eigen::Vector2d nominal_position_m(double lap_distance_m) const;
  Eigen::Vector2d nominal_direction(double lap_distance_m) const;
  FlightConfig config_;
  double a_ = 0.0, b_ = 0.0;
  double length_m_ = 0.0;
  size_t lap_count_ = 1;
  std::vector<LapOffset> lap_offsets_;  // one per lap; the first is zero
  std::vector<double> theta_;           // dense samples of the parameter...
  std::vector<double> arc_length_;      // ...and the length travelled up to each
};

// The ground-truth sensor pose T_world_sensor `flight_time_s` seconds after the start (stamp
// config.start_time_s): yaw along the direction of travel plus the sweep (heading + amplitude *
// sin(2 pi t / period)), roll and pitch from the horizontal acceleration, as a multicopter tilts
// to produce it. A function of time, so a sweeping LiDAR casts each column from its own pose. Past
// the end of the path the drone hovers there, still sweeping its yaw.
Eigen::Isometry3d truth_pose_at(const Figure8Path& path, const FlightConfig& config,
                                double flight_time_s);

// Ground-truth sensor poses at the scan rate (truth_pose_at sampled), from the start to the end
// of the path.
std::vector<StampedIsometry> simulate_truth(const Figure8Path& path, const FlightConfig& config);

// The largest yaw rate of the truth (deg/s), from the yaw of the poses (atan2 of the rotation's
// first column) sampled every `step_s` over the whole flight.
double peak_yaw_rate_deg_per_s(const Figure8Path& path, const FlightConfig& config,
                               double step_s = 0.01);

// Odometry for `truth` (first pose exact). Deterministic from `seed`.
std::vector<StampedIsometry> simulate_odometry(const std::vector<StampedIsometry>& truth,
                                               const DriftConfig& config, uint64_t seed);

// The odometry at `stamp_s`, given the samples `truth` and `odometry` (same stamps, increasing)
// and the truth at `stamp_s`: the drift of the samples on either side (odometry * truth^-1, a yaw
// rotation and a translation) interpolated linearly in yaw and translation, applied to
// `truth_at_stamp`. At a sample's own stamp it is that sample; before the first or after the last
// sample the nearest sample's drift holds.
Eigen::Isometry3d odometry_at(const std::vector<StampedIsometry>& truth,
                              const std::vector<StampedIsometry>& odometry, double stamp_s,
                              const Eigen::Isometry3d& truth_at_stamp);

// Distance between the last odometry and truth positions.
double final_drift_m(const std::vector<StampedIsometry>& truth,
                     const std::vector<StampedIsometry>& odometry);

// A flight's poses as an io::Trajectory with orientations, for TUM files and trajectory
// evaluation.
io::Trajectory to_trajectory(const std::vector<StampedIsometry>& poses);

}  // namespace sim
}  // namespace covox

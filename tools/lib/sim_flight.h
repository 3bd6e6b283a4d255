#pragma once
// The simulated flight: a figure-8 (lemniscate of Gerono, x = A sin(theta), y = B sin(theta)
// cos(theta)) flown at constant speed, starting at the crossing point, whose +x lobe end runs
// straight through a building (the "passage": the lobe is nearly straight there, with a curvature
// radius of B^2 / A). Altitude drops from cruise to indoor height around the passage.
// Orientation: yaw along the direction of travel, roll and pitch from the horizontal acceleration
// as a multicopter tilts to produce it.
//
// Odometry = truth + drift, as visual-inertial odometry drifts in the four unobservable degrees
// of freedom (x, y, z, yaw): a yaw error that grows as a random walk with a bias rotates every
// later displacement, and the position picks up its own random walk with a bias.
#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/io/trajectory_io.h"

namespace covox {
namespace sim {

struct FlightConfig {
  double path_length_m = 400.0;
  double speed_m_per_s = 2.0;
  double scan_rate_hz = 10.0;
  double lobe_half_length_m =
      55.0;  // A: the figure 8 spans x in [-A, A]; B follows from the length
  double cruise_altitude_m = 3.5;
  double indoor_altitude_m = 1.6;
  // The altitude is indoor within this horizontal distance of the passage centre, cruise beyond
  // it plus the transition length.
  double indoor_radius_m = 10.0;
  double altitude_transition_m = 12.0;
  double start_time_s = 1000.0;
};

struct DriftConfig {
  Eigen::Vector3d bias_velocity_m_per_s = Eigen::Vector3d(0.008, -0.006, 0.0015);
  double yaw_bias_deg_per_s = 0.015;
  double translation_random_walk_m_per_sqrt_s = 0.01;
  double yaw_random_walk_deg_per_sqrt_s = 0.03;
  // If the odometry ends closer than this to the truth, the whole drift (biases and random walks
  // alike) is scaled up until it does not: the default flight has at least this much drift.
  double min_final_drift_m = 3.0;

  // Every rate (biases and random walks) multiplied by `factor` >= 0; factor 0 also drops the
  // least final drift, so the odometry equals the truth (simulate_flight --drift-scale 0: the
  // mapping's own error without drift to correct).
  DriftConfig scaled(double factor) const;
};

struct StampedIsometry {
  double stamp_s = 0.0;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // T_world_sensor
};

class Figure8Path {
 public:
  // Throws covox::Error when the length cannot be reached with the lobe half length (it must be
  // more than about 4.1 A and less than about 9 A).
  explicit Figure8Path(const FlightConfig& config);

  double length_m() const { return arc_length_.back(); }
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
  double theta_at(double distance_m) const;
  FlightConfig config_;
  double a_ = 0.0, b_ = 0.0;
  std::vector<double> theta_;       // dense samples of the parameter...
  std::vector<double> arc_length_;  // ...and the length travelled up to each
};

// Ground-truth sensor poses at the scan rate, from the start to the end of the path.
std::vector<StampedIsometry> simulate_truth(const Figure8Path& path, const FlightConfig& config);

// Odometry for `truth` (first pose exact). Deterministic from `seed`.
std::vector<StampedIsometry> simulate_odometry(const std::vector<StampedIsometry>& truth,
                                               const DriftConfig& config, uint64_t seed);

// Distance between the last odometry and truth positions.
double final_drift_m(const std::vector<StampedIsometry>& truth,
                     const std::vector<StampedIsometry>& odometry);

// A flight's poses as an io::Trajectory with orientations, for TUM files and trajectory
// evaluation.
io::Trajectory to_trajectory(const std::vector<StampedIsometry>& poses);

}  // namespace sim
}  // namespace covox

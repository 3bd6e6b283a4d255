#include "sim/sim_flight.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "covoxslam/core/error.h"
#include "sim/sim_random.h"

namespace covox {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kGravity_m_per_s2 = 9.81;
constexpr int kPathSamples = 20000;

double lemniscate_length(double a, double b) {
  double length = 0.0;
  Eigen::Vector2d previous(0.0, 0.0);
  for (int i = 1; i <= kPathSamples; ++i) {
    const double theta = 2.0 * kPi * i / kPathSamples;
    const Eigen::Vector2d p(a * std::sin(theta), b * std::sin(theta) * std::cos(theta));
    length += (p - previous).norm();
    previous = p;
  }
  return length;
}

double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

Eigen::Matrix3d yaw_rotation(double yaw_rad) {
  return Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

std::vector<StampedIsometry> drifted(const std::vector<StampedIsometry>& truth,
                                     const DriftConfig& config, uint64_t seed, double scale) {
  Random random(stream_seed(seed, 0x0D0D0D));
  std::vector<StampedIsometry> odometry(truth.size());
  if (truth.empty()) return odometry;
  const double deg = kPi / 180.0;
  odometry[0] = truth[0];
  double yaw_error_rad = 0.0;
  Eigen::Vector3d position_m = truth[0].pose.translation();
  for (size_t k = 1; k < truth.size(); ++k) {
    const double dt = truth[k].stamp_s - truth[k - 1].stamp_s;
    const double root_dt = std::sqrt(dt);
    // Drift increments of this step (all scaled together so the shape of the drift is kept).
    Eigen::Vector3d translation_step = config.bias_velocity_m_per_s * dt;
    for (int axis = 0; axis < 3; ++axis) {
      translation_step[axis] +=
          config.translation_random_walk_m_per_sqrt_s * root_dt * random.normal();
    }
    const double yaw_step = (config.yaw_bias_deg_per_s * dt +
                             config.yaw_random_walk_deg_per_sqrt_s * root_dt * random.normal()) *
                            deg;
    // The true displacement, seen through the odometry's yaw error, plus the translation drift.
    const Eigen::Vector3d displacement =
        truth[k].pose.translation() - truth[k - 1].pose.translation();
    position_m += yaw_rotation(yaw_error_rad) * displacement + scale * translation_step;
    yaw_error_rad += scale * yaw_step;
    odometry[k].stamp_s = truth[k].stamp_s;
    odometry[k].pose.linear() = yaw_rotation(yaw_error_rad) * truth[k].pose.linear();
    odometry[k].pose.translation() = position_m;
  }
  return odometry;
}

// The drift scaled until the odometry ends final_drift_percent of the distance flown from the
// truth (within a percent of that; the final drift is close to linear in the scale).
std::vector<StampedIsometry> odometry_drifting_by_percent(const std::vector<StampedIsometry>& truth,
                                                          const DriftConfig& config,
                                                          uint64_t seed) {
  double distance_m = 0.0;
  for (size_t k = 1; k < truth.size(); ++k)
    distance_m += (truth[k].pose.translation() - truth[k - 1].pose.translation()).norm();
  const double target_m = 0.01 * config.final_drift_percent * distance_m;
  double scale = 1.0;
  std::vector<StampedIsometry> odometry = drifted(truth, config, seed, scale);
  for (int attempt = 0; attempt < 12 && truth.size() > 1; ++attempt) {
    const double drift = final_drift_m(truth, odometry);
    if (std::abs(drift - target_m) <= 0.01 * target_m) break;
    scale *= drift > 1e-6 ? target_m / drift : 2.0;
    odometry = drifted(truth, config, seed, scale);
  }
  return odometry;
}

// The number of laps and the length of one: the configured lap length, or the path split into
// the fewest whole laps no longer than 9 A (nor than `longest_m`, the longest a figure 8 of half
// length A can be). A path shorter than `shortest_m` (the shortest such figure 8) flies the start
// of one lap: the default flight's where these lobes can fly it, so a short flight is the start
// of the default one. `whole` tells whether the laps fill the path.
size_t plan_laps(const FlightConfig& config, double shortest_m, double longest_m, double* lap_m,
                 bool* whole) {
  if (config.lap_length_m > 0.0) {
    *lap_m = config.lap_length_m;
    const double laps = std::max(1.0, std::ceil(config.path_length_m / *lap_m - 1e-9));
    *whole = std::abs(config.path_length_m - laps * *lap_m) <= 1e-9 * config.path_length_m;
    return static_cast<size_t>(laps);
  }
  const double laps = std::max(
      1.0, std::ceil(config.path_length_m / std::min(longest_m, 9.0 * config.lobe_half_length_m)));
  *lap_m = config.path_length_m / laps;
  *whole = true;
  if (*lap_m < shortest_m) {
    const double longest_lap_m = std::min(longest_m, 9.0 * config.lobe_half_length_m);
    *lap_m = std::clamp(FlightConfig().path_length_m, shortest_m, longest_lap_m);
    *whole = false;
  }
  return static_cast<size_t>(laps);
}

// A value for a message: as short as it reads ("10", "0.25").
std::string shortest(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", value);
  return text;
}

// The yaw sweep and the odometry rate; throws covox::Error naming the parameter.
void validate_motion(const FlightConfig& config) {
  if (!(config.yaw_sweep_amplitude_deg >= 0.0 && config.yaw_sweep_amplitude_deg <= 90.0)) {
    throw Error(
        "flight: the yaw sweep amplitude (--yaw-sweep-amplitude-deg) must be in [0, 90] "
        "degrees, got " +
        shortest(config.yaw_sweep_amplitude_deg));
  }
  if (!(config.yaw_sweep_period_s > 0.0 && std::isfinite(config.yaw_sweep_period_s))) {
    throw Error("flight: the yaw sweep period (--yaw-sweep-period-s) must be positive, got " +
                shortest(config.yaw_sweep_period_s));
  }
  const double per_scan = config.odometry_rate_hz / config.scan_rate_hz;
  if (!(per_scan >= 1.0 && per_scan <= 1000.0) ||
      std::abs(per_scan - std::round(per_scan)) > 1e-9 * per_scan) {
    throw Error(
        "flight: the odometry rate (--odometry-rate-hz) must be a whole multiple of the "
        "scan rate of " +
        shortest(config.scan_rate_hz) + " Hz, at most 1000 times it, got " +
        shortest(config.odometry_rate_hz) + " Hz");
  }
}

}  // namespace

Figure8Path::Figure8Path(const FlightConfig& config)
    : config_(config), a_(config.lobe_half_length_m) {
  if (!(config.lobe_half_length_m > 0.0) || !(config.path_length_m > 0.0) ||
      !(config.speed_m_per_s > 0.0) || !(config.scan_rate_hz > 0.0) ||
      !(config.lap_length_m >= 0.0) || !(config.lap_blend_length_m > 0.0)) {
    throw Error(
        "flight: lobe half length, path length, speed, scan rate and lap blend length must be "
        "positive, the lap length positive or 0");
  }
  validate_motion(config);
  // The length grows with B: bisect for the B that gives the requested lap length.
  double low = 0.05 * a_, high = 3.0 * a_;
  const double shortest_m = lemniscate_length(a_, low), longest_m = lemniscate_length(a_, high);
  double lap_m = 0.0;
  bool whole_laps = false;
  lap_count_ = plan_laps(config, shortest_m, longest_m, &lap_m, &whole_laps);
  if (shortest_m > lap_m || longest_m < lap_m) {
    // The length scales with A at a fixed B / A: the half lengths that can fly this lap.
    char text[320];
    std::snprintf(text, sizeof(text),
                  "flight: a figure 8 of lobe half length %.1f m cannot fly a lap of %.1f m; "
                  "change the lobe half length (--lobe-half-length-m, %.1f to %.1f m for this "
                  "lap), the lap length (--lap-length-m) or the flight length (--path-length-m, "
                  "--duration-s)",
                  a_, lap_m, a_ * lap_m / longest_m, a_ * lap_m / shortest_m);
    throw Error(text);
  }
  for (int iteration = 0; iteration < 60; ++iteration) {
    const double middle = 0.5 * (low + high);
    (lemniscate_length(a_, middle) < lap_m ? low : high) = middle;
  }
  b_ = 0.5 * (low + high);
  theta_.resize(kPathSamples + 1);
  arc_length_.resize(kPathSamples + 1);
  Eigen::Vector2d previous(0.0, 0.0);
  for (int i = 0; i <= kPathSamples; ++i) {
    theta_[i] = 2.0 * kPi * i / kPathSamples;
    const Eigen::Vector2d p(a_ * std::sin(theta_[i]),
                            b_ * std::sin(theta_[i]) * std::cos(theta_[i]));
    arc_length_[i] = i == 0 ? 0.0 : arc_length_[i - 1] + (p - previous).norm();
    previous = p;
  }
  length_m_ =
      whole_laps ? static_cast<double>(lap_count_) * arc_length_.back() : config.path_length_m;
  lap_offsets_.resize(lap_count_);
  for (size_t lap = 1; lap < lap_count_; ++lap) {
    Random random(stream_seed(config.variation_seed, 0x1A95, lap));
    lap_offsets_[lap].lateral_m = config.lap_lateral_offset_m * random.uniform(-1.0, 1.0);
    lap_offsets_[lap].altitude_m = config.lap_altitude_offset_m * random.uniform(-1.0, 1.0);
  }
}

size_t Figure8Path::lap_at(double distance_m, double* into_lap_m) const {
  const double lap_m = lap_length_m();
  size_t lap = 0;
  if (lap_count_ > 1 && distance_m > lap_m) {
    lap = std::min(static_cast<size_t>(distance_m / lap_m), lap_count_ - 1);
  }
  *into_lap_m = distance_m - static_cast<double>(lap) * lap_m;
  return lap;
}

double Figure8Path::theta_at(double lap_distance_m) const {
  lap_distance_m = std::clamp(lap_distance_m, 0.0, lap_length_m());
  const size_t after =
      std::min<size_t>(std::lower_bound(arc_length_.begin(), arc_length_.end(), lap_distance_m) -
                           arc_length_.begin(),
                       arc_length_.size() - 1);
  if (after == 0) return theta_[0];
  const double fraction =
      (lap_distance_m - arc_length_[after - 1]) / (arc_length_[after] - arc_length_[after - 1]);
  return theta_[after - 1] + fraction * (theta_[after] - theta_[after - 1]);
}

Eigen::Vector2d Figure8Path::nominal_position_m(double lap_distance_m) const {
  const double theta = theta_at(lap_distance_m);
  return Eigen::Vector2d(a_ * std::sin(theta), b_ * std::sin(theta) * std::cos(theta));
}

Eigen::Vector2d Figure8Path::nominal_direction(double lap_distance_m) const {
  const double theta = theta_at(lap_distance_m);
  return Eigen::Vector2d(a_ * std::cos(theta), b_ * std::cos(2.0 * theta)).normalized();
}

double Figure8Path::indoor_blend(const Eigen::Vector2d& nominal_m) const {
  const double d = (nominal_m - passage_centre_m()).norm();
  return smoothstep((d - config_.indoor_radius_m) / config_.altitude_transition_m);
}

Figure8Path::LapOffset Figure8Path::offset_at(double distance_m) const {
  double into_lap_m = 0.0;
  const size_t lap = lap_at(distance_m, &into_lap_m);
  if (lap == 0) return LapOffset();
  // From the previous lap's offsets to this lap's, with zero slope at both ends of the blend:
  // the path's direction is continuous across the lap boundary.
  const double blend_m = std::min(config_.lap_blend_length_m, 0.125 * lap_length_m());
  const double t = smoothstep(into_lap_m / blend_m);
  const double near_passage = 0.25 + 0.75 * indoor_blend(nominal_position_m(into_lap_m));
  const LapOffset& before = lap_offsets_[lap - 1];
  const LapOffset& after = lap_offsets_[lap];
  LapOffset offset;
  offset.lateral_m = near_passage * (before.lateral_m + t * (after.lateral_m - before.lateral_m));
  offset.altitude_m =
      near_passage * (before.altitude_m + t * (after.altitude_m - before.altitude_m));
  return offset;
}

Eigen::Vector2d Figure8Path::position_m(double distance_m) const {
  double into_lap_m = 0.0;
  const size_t lap = lap_at(distance_m, &into_lap_m);
  const Eigen::Vector2d nominal = nominal_position_m(into_lap_m);
  if (lap == 0) return nominal;
  const Eigen::Vector2d tangent = nominal_direction(into_lap_m);
  return nominal + offset_at(distance_m).lateral_m * Eigen::Vector2d(-tangent.y(), tangent.x());
}

Eigen::Vector2d Figure8Path::direction(double distance_m) const {
  double into_lap_m = 0.0;
  if (lap_at(distance_m, &into_lap_m) == 0) return nominal_direction(into_lap_m);
  // The offset path's tangent by central differences (the offsets vary slowly along the lap).
  const double h_m = 0.01;
  const double ahead = std::min(distance_m + h_m, length_m_);
  return (position_m(ahead) - position_m(ahead - 2.0 * h_m)).normalized();
}

double Figure8Path::altitude_m(double distance_m) const {
  double into_lap_m = 0.0;
  const size_t lap = lap_at(distance_m, &into_lap_m);
  const double blend = indoor_blend(nominal_position_m(into_lap_m));
  const double altitude_m =
      config_.indoor_altitude_m + blend * (config_.cruise_altitude_m - config_.indoor_altitude_m);
  return lap == 0 ? altitude_m : altitude_m + offset_at(distance_m).altitude_m;
}

double Figure8Path::passage_x_at_m(double y_m) const {
  // On theta in [pi/4, 3pi/4] (the +x lobe end) y = B/2 sin(2 theta) falls monotonically.
  double low = 0.25 * kPi, high = 0.75 * kPi;
  for (int iteration = 0; iteration < 60; ++iteration) {
    const double middle = 0.5 * (low + high);
    (b_ * std::sin(middle) * std::cos(middle) > y_m ? low : high) = middle;
  }
  return a_ * std::sin(0.5 * (low + high));
}

Eigen::Isometry3d truth_pose_at(const Figure8Path& path, const FlightConfig& config,
                                double flight_time_s) {
  const double duration_s = path.length_m() / config.speed_m_per_s;
  const auto position = [&](double t_s) {
    const double s = std::min(t_s, duration_s) * config.speed_m_per_s;
    const Eigen::Vector2d xy = path.position_m(s);
    return Eigen::Vector3d(xy.x(), xy.y(), path.altitude_m(s));
  };
  const double t = flight_time_s;
  const Eigen::Vector2d heading = path.direction(std::min(t, duration_s) * config.speed_m_per_s);
  const double sweep_rad = config.yaw_sweep_amplitude_deg * kPi / 180.0 *
                           std::sin(2.0 * kPi * t / config.yaw_sweep_period_s);
  const double yaw = std::atan2(heading.y(), heading.x()) + sweep_rad;
  // Horizontal acceleration by central differences (one step of 0.05 s), in the yawed frame.
  // At the ends the stencil moves inwards by a step: the path has no point before its start or
  // after its end, and a stencil clamped there divides the velocity by h (the first and last
  // poses were tilted by 76 degrees).
  const double h = 0.05;
  const double centre = std::min(std::max(t, h), std::max(h, duration_s - h));
  const Eigen::Vector3d acceleration =
      (position(centre + h) - 2.0 * position(centre) + position(centre - h)) / (h * h);
  const Eigen::Vector3d local = yaw_rotation(-yaw) * acceleration;
  // Thrust tilts towards the acceleration: forward needs pitch down (positive about y in a
  // forward-left-up frame), left needs roll to the left (negative about x).
  const double pitch = std::atan2(local.x(), kGravity_m_per_s2);
  const double roll = -std::atan2(local.y(), kGravity_m_per_s2);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                   Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                      .toRotationMatrix();
  pose.translation() = position(t);
  return pose;
}

std::vector<StampedIsometry> simulate_truth(const Figure8Path& path, const FlightConfig& config) {
  const double dt = 1.0 / config.scan_rate_hz;
  const double duration_s = path.length_m() / config.speed_m_per_s;
  const size_t count = static_cast<size_t>(std::floor(duration_s * config.scan_rate_hz)) + 1;
  std::vector<StampedIsometry> poses(count);
  for (size_t k = 0; k < count; ++k) {
    const double t = k * dt;
    poses[k].stamp_s = config.start_time_s + t;
    poses[k].pose = truth_pose_at(path, config, t);
  }
  return poses;
}

double peak_yaw_rate_deg_per_s(const Figure8Path& path, const FlightConfig& config, double step_s) {
  const double duration_s = path.length_m() / config.speed_m_per_s;
  const auto yaw_at = [&](double t) {
    const Eigen::Matrix3d rotation = truth_pose_at(path, config, t).linear();
    return std::atan2(rotation(1, 0), rotation(0, 0));
  };
  double peak_rad_per_s = 0.0, previous = yaw_at(0.0);
  for (double t = step_s; t <= duration_s; t += step_s) {
    const double yaw = yaw_at(t);
    const double change = std::remainder(yaw - previous, 2.0 * kPi);
    peak_rad_per_s = std::max(peak_rad_per_s, std::abs(change) / step_s);
    previous = yaw;
  }
  return peak_rad_per_s * 180.0 / kPi;
}

DriftConfig DriftConfig::scaled(double factor) const {
  if (!(factor >= 0.0) || !std::isfinite(factor)) {
    throw Error("drift: the scale factor must be finite and >= 0, got " + std::to_string(factor));
  }
  DriftConfig result = *this;
  result.bias_velocity_m_per_s *= factor;
  result.yaw_bias_deg_per_s *= factor;
  result.translation_random_walk_m_per_sqrt_s *= factor;
  result.yaw_random_walk_deg_per_sqrt_s *= factor;
  if (factor == 0.0) {
    result.min_final_drift_m = 0.0;
    result.final_drift_percent = 0.0;
  }
  return result;
}

std::vector<StampedIsometry> simulate_odometry(const std::vector<StampedIsometry>& truth,
                                               const DriftConfig& config, uint64_t seed) {
  if (config.final_drift_percent > 0.0) return odometry_drifting_by_percent(truth, config, seed);
  double scale = 1.0;
  std::vector<StampedIsometry> odometry = drifted(truth, config, seed, scale);
  // A few rescalings suffice: the final drift is close to linear in the scale.
  for (int attempt = 0; attempt < 8 && truth.size() > 1; ++attempt) {
    const double drift = final_drift_m(truth, odometry);
    if (drift >= config.min_final_drift_m) break;
    scale *= drift > 1e-6 ? 1.05 * config.min_final_drift_m / drift : 2.0;
    odometry = drifted(truth, config, seed, scale);
  }
  return odometry;
}

Eigen::Isometry3d odometry_at(const std::vector<StampedIsometry>& truth,
                              const std::vector<StampedIsometry>& odometry, double stamp_s,
                              const Eigen::Isometry3d& truth_at_stamp) {
  if (truth.empty() || odometry.size() != truth.size()) {
    throw Error("odometry_at: " + std::to_string(odometry.size()) + " odometry samples for " +
                std::to_string(truth.size()) + " truth samples");
  }
  // The first sample after stamp_s.
  const size_t after = static_cast<size_t>(
      std::upper_bound(truth.begin(), truth.end(), stamp_s,
                       [](double s, const StampedIsometry& sample) { return s < sample.stamp_s; }) -
      truth.begin());
  if (after > 0 && truth[after - 1].stamp_s == stamp_s) return odometry[after - 1].pose;
  const auto drift = [&](size_t k) { return odometry[k].pose * truth[k].pose.inverse(); };
  if (after == 0) return drift(0) * truth_at_stamp;
  if (after == truth.size()) return drift(after - 1) * truth_at_stamp;
  const Eigen::Isometry3d before = drift(after - 1), later = drift(after);
  const double fraction =
      (stamp_s - truth[after - 1].stamp_s) / (truth[after].stamp_s - truth[after - 1].stamp_s);
  const auto yaw_of = [](const Eigen::Isometry3d& T) {
    return std::atan2(T.linear()(1, 0), T.linear()(0, 0));
  };
  const double yaw_before = yaw_of(before);
  const double yaw_change = std::remainder(yaw_of(later) - yaw_before, 2.0 * kPi);
  Eigen::Isometry3d interpolated = Eigen::Isometry3d::Identity();
  interpolated.linear() = yaw_rotation(yaw_before + fraction * yaw_change);
  interpolated.translation() =
      before.translation() + fraction * (later.translation() - before.translation());
  return interpolated * truth_at_stamp;
}

double final_drift_m(const std::vector<StampedIsometry>& truth,
                     const std::vector<StampedIsometry>& odometry) {
  if (truth.empty() || odometry.size() != truth.size()) return 0.0;
  return (truth.back().pose.translation() - odometry.back().pose.translation()).norm();
}

io::Trajectory to_trajectory(const std::vector<StampedIsometry>& poses) {
  io::Trajectory trajectory;
  trajectory.poses.reserve(poses.size());
  for (const StampedIsometry& stamped : poses) {
    io::StampedPose pose;
    pose.timestamp_s = stamped.stamp_s;
    pose.position_m = stamped.pose.translation();
    // Normalised so that a rotation block a little off orthonormal (poses composed over many
    // steps) still gives the unit quaternion TUM files expect.
    pose.orientation = Eigen::Quaterniond(stamped.pose.linear()).normalized();
    trajectory.poses.push_back(pose);
  }
  return trajectory;
}

}  // namespace sim
}  // namespace covox

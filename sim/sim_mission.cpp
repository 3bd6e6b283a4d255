#include "sim/sim_mission.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "covoxslam/core/error.h"

#include "sim/sim_random.h"

namespace covox {
namespace sim {

const char kSimulationUsage[] =
    "  --seed N                 world, lap, drift and noise seed (default 1)\n"
    "  --columns N              LiDAR horizontal resolution (default 1024, OS1-64; 512 or 256 for "
    "fast CPU runs)\n"
    "  --rows N                 LiDAR beams (default 64)\n"
    "  --range-noise-m S        range noise standard deviation (default 0.02)\n"
    "  --dropout P              probability that a beam returns nothing (default 0.01)\n"
    "  --max-range-m R          LiDAR range limit (default 120)\n"
    "  --instantaneous-scan     cast every beam of a scan at once from the pose at its stamp (no\n"
    "                           per-point times); by default the columns fire one after the other\n"
    "                           over the 0.1 s sweep along the flight, so scans are distorted by\n"
    "                           the motion as a real spinning LiDAR's are, with the time of each\n"
    "                           point in the cloud's field t\n"
    "  --path-length-m L        flight length (default 400: one lap of the figure 8)\n"
    "  --duration-s S           flight length as a duration at the speed (instead of "
    "--path-length-m)\n"
    "  --lobe-half-length-m A   half the figure 8's extent along x (default 55)\n"
    "  --lap-length-m L         one lap (default: the flight split into the fewest whole laps\n"
    "                           of at most 9 A; a flight shorter than any lap flies the start\n"
    "                           of the default flight's; laps after the first are shifted by\n"
    "                           up to 1 m sideways and 0.5 m in altitude)\n"
    "  --speed-m-per-s V        flight speed (default 2)\n"
    "  --yaw-sweep-amplitude-deg A\n"
    "                           the drone looks around: yaw = direction of travel\n"
    "                           + A sin(2 pi t / period) (default 30; 0: facing forward)\n"
    "  --yaw-sweep-period-s P   period of that sweep (default 4: with the path's turns, yaw rates\n"
    "                           up to about 60 deg/s)\n"
    "  --odometry-rate-hz R     odometry poses a second, the bag's tf odom -> imu (default 100; a\n"
    "                           whole multiple of the 10 Hz scan rate)\n"
    "  --min-drift-m D          least final odometry drift (default 3)\n"
    "  --drift-percent P        odometry ends P % of the distance flown off the truth (instead "
    "of\n"
    "                           --min-drift-m; real LiDAR or visual odometry: 0.5 to 2)\n"
    "  --drift-scale F          multiplies every drift rate (default 1; 0: odometry equals the "
    "truth,\n"
    "                           which isolates the mapping's own error)\n";

namespace {

// Bounds of the simulator's options: beyond them a run would not fit in memory or time (a
// 100 km path, a day of flight, an 8192 x 1024 beam scan).
constexpr int64_t kMaxColumns = 8192;
constexpr int64_t kMaxRows = 1024;
constexpr double kMaxPathLengthM = 100000.0;
constexpr double kMaxDurationS = 86400.0;

void read_lidar_options(tools::CommandLine& args, LidarConfig* lidar) {
  lidar->columns =
      static_cast<int>(args.positive_integer("--columns", lidar->columns, kMaxColumns));
  lidar->rows = static_cast<int>(args.positive_integer("--rows", lidar->rows, kMaxRows));
  lidar->range_noise_m = args.number("--range-noise-m", lidar->range_noise_m, 0.0, 10.0);
  lidar->dropout_probability = args.number("--dropout", lidar->dropout_probability, 0.0, 1.0);
  lidar->max_range_m = args.number("--max-range-m", lidar->max_range_m, 0.1, 1000.0);
  lidar->instantaneous = args.flag("--instantaneous-scan");
}

void read_flight_options(tools::CommandLine& args, FlightConfig* flight) {
  const double unset = std::numeric_limits<double>::quiet_NaN();
  const double path_length_m = args.number("--path-length-m", unset, 1.0, kMaxPathLengthM);
  const double duration_s = args.number("--duration-s", unset, 0.1, kMaxDurationS);
  flight->speed_m_per_s = args.number("--speed-m-per-s", flight->speed_m_per_s, 0.01, 100.0);
  flight->lobe_half_length_m =
      args.number("--lobe-half-length-m", flight->lobe_half_length_m, 1.0, 10000.0);
  flight->lap_length_m = args.number("--lap-length-m", flight->lap_length_m, 0.0, kMaxPathLengthM);
  flight->yaw_sweep_amplitude_deg =
      args.number("--yaw-sweep-amplitude-deg", flight->yaw_sweep_amplitude_deg, 0.0, 180.0);
  flight->yaw_sweep_period_s =
      args.number("--yaw-sweep-period-s", flight->yaw_sweep_period_s, 0.1, 1.0e6);
  flight->odometry_rate_hz =
      args.number("--odometry-rate-hz", flight->odometry_rate_hz, 1.0, 10000.0);
  // The yaw sweep and the odometry rate are checked with the path (Figure8Path), which names them.
  if (!(flight->speed_m_per_s > 0.0)) args.fail("--speed-m-per-s must be positive");
  if (!(flight->lobe_half_length_m > 0.0)) args.fail("--lobe-half-length-m must be positive");
  if (!(flight->lap_length_m >= 0.0)) args.fail("--lap-length-m must be positive");
  if (!std::isnan(path_length_m) && !std::isnan(duration_s))
    args.fail("give --path-length-m or --duration-s, not both");
  if (!std::isnan(duration_s)) {
    if (!(duration_s > 0.0 && std::isfinite(duration_s)))
      args.fail("--duration-s must be positive");
    flight->path_length_m = duration_s * flight->speed_m_per_s;
  } else if (!std::isnan(path_length_m)) {
    if (!(path_length_m > 0.0 && std::isfinite(path_length_m)))
      args.fail("--path-length-m must be positive");
    flight->path_length_m = path_length_m;
  }
}

void read_drift_options(tools::CommandLine& args, SimulationOptions* options) {
  const double unset = std::numeric_limits<double>::quiet_NaN();
  DriftConfig& drift = options->drift;
  const double min_drift_m = args.number("--min-drift-m", unset, 0.0, 10000.0);
  const double percent = args.number("--drift-percent", unset, 0.0, 100.0);
  options->drift_scale = args.number("--drift-scale", options->drift_scale, 0.0, 1000.0);
  if (!(options->drift_scale >= 0.0 && std::isfinite(options->drift_scale)))
    args.fail("--drift-scale must be a number >= 0");
  if (!std::isnan(min_drift_m) && !std::isnan(percent))
    args.fail("give --min-drift-m or --drift-percent, not both");
  if (!std::isnan(min_drift_m)) {
    if (!(min_drift_m >= 0.0)) args.fail("--min-drift-m must be >= 0");
    drift.min_final_drift_m = min_drift_m;
  }
  if (!std::isnan(percent)) {
    if (!(percent > 0.0 && percent < 100.0)) args.fail("--drift-percent must be in (0, 100)");
    if (options->drift_scale == 0.0)
      args.fail("--drift-scale 0 (odometry = truth) cannot end --drift-percent off");
    drift.final_drift_percent = percent;
  }
}

}  // namespace

SimulationOptions read_simulation_options(tools::CommandLine& args) {
  SimulationOptions options;
  options.seed =
      static_cast<uint64_t>(args.integer("--seed", 1, 0, std::numeric_limits<int64_t>::max()));
  read_lidar_options(args, &options.lidar);
  read_flight_options(args, &options.flight);
  read_drift_options(args, &options);
  options.flight.variation_seed = options.seed;
  return options;
}

SimulatedMission::SimulatedMission(const SimulationOptions& options, size_t max_scans)
    : options_(options), path_((validate(options.lidar), options.flight)) {
  site_ = build_site(SiteConfig().scaled_to(path_), path_, options_.seed);
  flight_truth_ = simulate_truth(path_, options_.flight);
  flight_odometry_ =
      simulate_odometry(flight_truth_, options_.drift.scaled(options_.drift_scale), options_.seed);
  truth_ = flight_truth_;
  odometry_ = flight_odometry_;
  if (max_scans > 0 && max_scans < truth_.size()) {
    truth_.resize(max_scans);
    odometry_.resize(max_scans);
  }
}

Eigen::Isometry3d SimulatedMission::truth_at(double stamp_s) const {
  return truth_pose_at(path_, options_.flight, stamp_s - options_.flight.start_time_s);
}

Eigen::Isometry3d SimulatedMission::odometry_at(double stamp_s) const {
  return sim::odometry_at(flight_truth_, flight_odometry_, stamp_s, truth_at(stamp_s));
}

std::vector<double> SimulatedMission::odometry_stamps(size_t k) const {
  const double stamp_s = truth_.at(k).stamp_s;
  const int per_scan = static_cast<int>(
      std::lround(options_.flight.odometry_rate_hz / options_.flight.scan_rate_hz));
  std::vector<double> stamps;
  if (k == 0) stamps.push_back(stamp_s);
  for (int i = 1; i < per_scan; ++i) stamps.push_back(stamp_s + i * sweep_period_s() / per_scan);
  stamps.push_back(k + 1 < truth_.size() ? truth_[k + 1].stamp_s : stamp_s + sweep_period_s());
  return stamps;
}

SweepScan SimulatedMission::scan(size_t k) const {
  // The flight time of scan k as simulate_truth computes it, so that the pose at the sweep's
  // start is truth()[k] bit for bit.
  const double scan_time_s = static_cast<double>(k) * (1.0 / options_.flight.scan_rate_hz);
  if (k >= truth_.size()) {
    throw Error("scan " + std::to_string(k) + " asked of a mission of " +
                std::to_string(truth_.size()) + " scans");
  }
  const PoseAtTime pose_at = [&](double seconds_after_start) {
    return truth_pose_at(path_, options_.flight, scan_time_s + seconds_after_start);
  };
  return simulate_sweep(site_.world, options_.lidar, pose_at, sweep_period_s(),
                        stream_seed(options_.seed, 0x5CA7, k));
}

double SimulatedMission::distance_flown_m(size_t count) const {
  double distance_m = 0.0;
  for (size_t k = 1; k < std::min(count, truth_.size()); ++k)
    distance_m += (truth_[k].pose.translation() - truth_[k - 1].pose.translation()).norm();
  return distance_m;
}

std::string describe_flight(const SimulatedMission& mission) {
  const Figure8Path& path = mission.path();
  const SimulationOptions& options = mission.options();
  char text[320];
  std::snprintf(text, sizeof(text),
                "%.1f m in %zu lap%s of a %.1f m figure 8 (lobes %.1f x %.1f m) at %.1f m/s, %zu "
                "%s scans of %d x %d beams, seed %llu",
                path.length_m(), path.lap_count(), path.lap_count() == 1 ? "" : "s",
                path.lap_length_m(), 2.0 * path.lobe_half_length_m(), path.lobe_width_m(),
                options.flight.speed_m_per_s, mission.size(),
                options.lidar.instantaneous ? "instantaneous" : "distorted", options.lidar.columns,
                options.lidar.rows, static_cast<unsigned long long>(options.seed));
  return text;
}

}  // namespace sim
}  // namespace covox

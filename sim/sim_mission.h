#pragma once
// A whole simulated flight from the simulator's options: the site, the truth and odometry poses at
// the scan rate (a few hundred bytes a scan, kept; both also at any time in between), and the
// scans themselves, generated one at a time on demand so that memory stays flat in the flight's
// length. Each scan is a sweep: its columns fire one after the other along the true trajectory
// (sim_lidar.h), unless the LiDAR is instantaneous. simulate_flight (which writes
// a bag) and run_slam --simulate (which maps in process) both read their options through
// read_simulation_options and fly a SimulatedMission: the same options give the same scans.
#include <cstdint>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "covoxslam/core/vec3.h"
#include "sim/sim_flight.h"
#include "sim/sim_lidar.h"
#include "sim/sim_site.h"

namespace covox {
namespace sim {

struct SimulationOptions {
  uint64_t seed = 1;  // world, lap offsets, drift and sensor noise
  LidarConfig lidar;
  FlightConfig flight;
  DriftConfig drift;         // before drift_scale
  double drift_scale = 1.0;  // DriftConfig::scaled
};

// The usage lines of the options read_simulation_options knows.
extern const char kSimulationUsage[];

// Reads the simulator's options from `args`; a bad value or an impossible combination fails
// through args.fail, naming the option to change. Does not call args.finish().
SimulationOptions read_simulation_options(tools::CommandLine& args);

class SimulatedMission {
 public:
  // Builds the path, the site and the poses; `max_scans` > 0 keeps only the first scans (the
  // drift is that of the whole flight). Throws covox::Error for an impossible flight or LiDAR.
  explicit SimulatedMission(const SimulationOptions& options, size_t max_scans = 0);

  size_t size() const { return truth_.size(); }
  const SimulationOptions& options() const { return options_; }
  const Figure8Path& path() const { return path_; }
  const Site& site() const { return site_; }
  const std::vector<StampedIsometry>& truth() const { return truth_; }        // T_world_os1_sensor
  const std::vector<StampedIsometry>& odometry() const { return odometry_; }  // T_odom_os1_sensor

  // One sweep: the scan rate's period.
  double sweep_period_s() const { return 1.0 / options_.flight.scan_rate_hz; }
  // T_world_os1_sensor and T_odom_os1_sensor at any stamp (seconds on the scans' clock); at a
  // scan's stamp, that scan's truth() and odometry() pose. The odometry between the scan-rate
  // samples: sim::odometry_at over the whole flight's samples (also with `max_scans`).
  Eigen::Isometry3d truth_at(double stamp_s) const;
  Eigen::Isometry3d odometry_at(double stamp_s) const;
  // The stamps of the odometry samples that a bag must hold before scan `k`'s cloud and did not
  // hold before scan k - 1's: at the odometry rate from the scan's stamp (from the first scan's
  // for k = 0) up to the end of its sweep, which is the next scan's stamp (for the last scan,
  // its stamp plus the sweep period). Increasing.
  std::vector<double> odometry_stamps(size_t k) const;

  // Scan `k`: its points in the os1_sensor frame at their firing times and those times (none if
  // the LiDAR is instantaneous); the same for the same options and `k`, whatever the order scans
  // are asked for in and the thread count.
  SweepScan scan(size_t k) const;

  // Distance between the first `count` truth positions, one after the other.
  double distance_flown_m(size_t count) const;

 private:
  SimulationOptions options_;
  Figure8Path path_;
  Site site_;
  std::vector<StampedIsometry> truth_, odometry_;
  // The whole flight's samples, which the odometry between samples interpolates.
  std::vector<StampedIsometry> flight_truth_, flight_odometry_;
};

// One line describing the flight ("1200.0 m: 3 laps of a 400.0 m figure 8 ...").
std::string describe_flight(const SimulatedMission& mission);

}  // namespace sim
}  // namespace covox

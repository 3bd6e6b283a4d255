#pragma once
// A simulated flight as a ScanSource, generated in process: each scan is ray-cast when the runner
// asks for it, so a mission of any length maps without a bag and with memory flat in its length.
// The scans are those simulate_flight writes into its bag for the same options, read back as
// BagScanSource reads them: points in the os1_lidar frame in single precision, nearer than
// `min_range_m` left out, with the odometry pose of os1_lidar. A distorted scan (the default,
// sim_lidar.h) also carries each point's time (the bag's field t, nanoseconds, in seconds as a
// float: sim::point_time_s) and the odometry of os1_lidar at the first and last of those times
// (SourceScan::sweep, from SimulatedMission::odometry_at, which the bag's tf samples at 100 Hz);
// an instantaneous scan carries neither. The reference is the ground truth (positions and
// orientations of os1_lidar).
#include <memory>
#include <string>

#include "runner/scan_source.h"
#include "sim/sim_mission.h"

namespace covox {
namespace tools {

class SimScanSource : public ScanSource {
 public:
  // Throws covox::Error for an impossible flight or LiDAR. `max_scans` > 0: only the first scans.
  SimScanSource(const sim::SimulationOptions& options, double min_range_m, size_t max_scans = 0);
  size_t size() const override { return mission_.size(); }
  bool next(SourceScan* scan) override;
  std::string describe() const override;
  double duration_s() const override;

  const sim::SimulatedMission& mission() const { return mission_; }
  // Seconds spent generating the scans handed out so far (ray casting and frame change).
  double generation_s() const { return generation_s_; }

 private:
  sim::SimulatedMission mission_;
  double min_range_m_ = 0.0;
  size_t next_scan_ = 0;
  double generation_s_ = 0.0;
};

}  // namespace tools
}  // namespace covox

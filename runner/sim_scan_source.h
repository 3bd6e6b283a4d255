#pragma once
// A simulated flight as a ScanSource, generated in process: each scan is ray-cast when the runner
// asks for it, so a mission of any length maps without a bag and with memory flat in its length.
// It hands out what BagScanSource reads from the bag simulate_flight writes for the same options,
// bit for bit: points in the os1_lidar frame in single precision, nearer than `min_range_m` left
// out; the stamp as the bag stores it (whole nanoseconds); the odometry pose of os1_lidar there
// and, for a distorted scan (the default, sim_lidar.h), each point's time (the bag's field t,
// nanoseconds, in seconds as a float: sim::point_time_s) with the odometry at the first and last
// of those times (SourceScan::sweep). Those poses are looked up, as the bag route does, in the tf
// the bag holds around the sweep (sim::sweep_tf: the odometry sampled at its rate, 100 Hz by
// default, and interpolated in between by TfBuffer), not evaluated at the times themselves: the
// two differ by the interpolation's error (micrometres, up to a hundredth of a degree), which the
// mapping amplifies into different registrations and trajectories. An instantaneous scan carries no
// times and no sweep. The reference is the ground truth (positions and orientations of os1_lidar).
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

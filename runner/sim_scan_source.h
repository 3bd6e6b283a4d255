#pragma once
// A simulated flight as a ScanSource, generated in process: each scan is ray-cast when the runner
// asks for it, so a mission of any length maps without a bag and with memory flat in its length.
// It hands out, bit for bit, what BagScanSource reads from the bag simulate_flight writes for the
// same options: os1_lidar points in single precision (nearer than `min_range_m` left out), the
// stamp in whole nanoseconds, the odometry there and, for a distorted scan, each point's time with
// the odometry at the first and last of them, looked up in the tf the bag holds around the sweep
// (sim::sweep_tf, interpolated by TfBuffer) rather than evaluated at those times: the micrometres
// between the two change registrations. The reference is the ground truth; design.md has the rest.
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

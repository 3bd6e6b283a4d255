#pragma once
// One offline SLAM run: every scan of a ScanSource through pipeline::SlamSystem as fast as the
// machine allows, with a progress bar, then the results and their evaluation against the
// source's reference. run_slam (one input, all outputs) and benchmark_accuracy (several inputs,
// one JSON) are both this.
//
// A recorded input should be processed completely, so unlike a live sensor the runner waits while
// a queue is full instead of letting it drop scans (drops are still counted and reported).
#include <string>
#include <vector>

#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/pipeline/slam_system.h"
#include "scan_source.h"
#include "trajectory_evaluation.h"

namespace covox {
namespace tools {

struct SlamRunOptions {
  size_t max_scans = 0;      // 0: all
  bool progress_bar = true;  // on stderr
  std::string map_path;      // non-empty: save the map (io/map_file.h) there
};

struct SlamRunResult {
  io::Trajectory corrected;  // covoxslam's sensor poses at the integrated scans' stamps
  io::Trajectory odometry;   // the odometry's sensor poses at the same scans (every scan given)
  Mesh mesh;                 // combined mesh at the corrected poses
  pipeline::SlamCounters counters;
  pipeline::SlamTimings timings;
  std::vector<pipeline::SubmapInfo> submaps;
  std::vector<pipeline::SubmapConstraint> constraints;  // the final pose graph's constraints
  size_t scans_given = 0;
  int64_t scans_dropped_by_source = 0;
  size_t map_blocks = 0;       // allocated TSDF blocks over all submaps
  double map_memory_mb = 0.0;  // their voxel payload
  double read_s = 0.0;         // reading and decoding the input
  double throttle_s = 0.0;     // input held back while a queue was full
  double finish_s = 0.0;       // flush and final optimisation
  double wall_s = 0.0;
  double input_duration_s = 0.0;  // sensor seconds covered
  double real_time_factor() const { return wall_s > 0.0 ? input_duration_s / wall_s : 0.0; }
};

// Runs `source` through a SlamSystem built from `config`. Throws covox::Error for a bad
// configuration or an input the source cannot read at all.
SlamRunResult run_slam_system(ScanSource& source, const pipeline::SlamConfig& config,
                              const SlamRunOptions& options);

// The trajectories against the source's reference (both evaluated the same way).
struct SlamRunEvaluation {
  bool available = false;  // false: no reference, or too few poses associate
  std::string problem;     // why not available
  TrajectoryEvaluation odometry;
  TrajectoryEvaluation corrected;
};
SlamRunEvaluation evaluate_slam_run(const ScanSource& source, const SlamRunResult& result,
                                    AlignmentMode alignment, double max_time_gap_s);

// How far the corrected trajectory lies from the odometry at the same stamps (positions; the
// world frame is the odometry frame of the first submap).
struct TrajectoryShift {
  double rms_m = 0.0;
  double max_m = 0.0;
};
TrajectoryShift trajectory_shift(const SlamRunResult& result);

// The per-module timing table and the counters, as the runner prints them.
void print_slam_run(const SlamRunResult& result, FILE* out);

}  // namespace tools
}  // namespace covox

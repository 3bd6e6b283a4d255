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
#include "runner/scan_source.h"
#include "eval/trajectory_evaluation.h"

namespace covox {
namespace tools {

struct SlamRunOptions {
  size_t max_scans = 0;      // 0: all
  bool progress_bar = true;  // on stderr
  std::string map_path;      // non-empty: save the map (io/map_file.h) there
  // A timeline sample every this many seconds of mission (sensor) time, and one at the end;
  // 0: no timeline.
  double timeline_interval_s = 0.0;
};

// The mission at one point of its sensor time: the state then (memory, map, graph) and what
// happened in the window since the previous sample (scan and submap costs). A figure with
// nothing to measure in its window (no scan, no submap) is NaN.
struct TimelineSample {
  double mission_s = 0.0;  // sensor seconds since the first scan
  bool end = false;        // taken after finish(): its window holds the flush and final solve
  double wall_s = 0.0;     // since the run began
  // This process's resident and peak resident memory (/proc/self/status VmRSS and VmHWM); NaN
  // where the file is missing.
  double host_rss_mb = 0.0;
  double host_peak_rss_mb = 0.0;
  // CUDA: the GPU's memory in use (total minus free, every process's); NaN on the CPU.
  double device_used_mb = 0.0;
  size_t map_blocks = 0;       // TSDF blocks of the submaps in the pose graph
  double map_memory_mb = 0.0;  // their voxel payload
  int64_t submaps = 0;         // in the pose graph
  // The window's scans: how many were integrated, and their frontend times (nearest rank).
  int64_t window_scans = 0;
  double scan_p50_ms = 0.0;
  double scan_p95_ms = 0.0;
  double scan_max_ms = 0.0;
  // The window's submaps: how many entered the graph, the mean time of each one's registration,
  // and the pose-graph solve time of the window divided by them (the optimisation cost a submap
  // brings).
  int64_t window_submaps = 0;
  double registration_ms_per_submap = 0.0;
  double solve_ms_per_submap = 0.0;
  int64_t window_optimizations = 0;
  // What a submap's registration did in the window: pairs attempted (its partners) and compact
  // submaps brought back for them, per submap.
  double partners_per_submap = 0.0;
  double restores_per_submap = 0.0;
  // Where the finished submaps were then (resident, compact, on disk) and their bytes.
  pipeline::SubmapStoreCounters memory;
};

struct SlamRunResult {
  io::Trajectory corrected;  // covoxslam's sensor poses at the integrated scans' stamps
  io::Trajectory odometry;   // the odometry's sensor poses at the same scans (every scan given)
  map::Mesh mesh;            // combined mesh at the corrected poses
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
  double input_duration_s = 0.0;         // sensor seconds covered
  std::vector<TimelineSample> timeline;  // options.timeline_interval_s > 0
  double map_save_s = 0.0;               // options.map_path: writing the map file
  double map_file_mb = 0.0;              // ... and its size
  double real_time_factor() const { return wall_s > 0.0 ? input_duration_s / wall_s : 0.0; }
};

// Runs `source` through a SlamSystem built from `config`. Throws covox::Error for a bad
// configuration, an input the source cannot read at all, or a run that integrated no scan (every
// scan dropped or refused); the map file is not written then.
SlamRunResult run_slam_system(ScanSource& source, const pipeline::SlamConfig& config,
                              const SlamRunOptions& options);

// The trajectories against the source's reference (both evaluated the same way).
struct SlamRunEvaluation {
  bool available = false;  // false: no reference, or too few poses associate
  std::string problem;     // why not available
  eval::TrajectoryEvaluation odometry;
  eval::TrajectoryEvaluation corrected;
};
SlamRunEvaluation evaluate_slam_run(const ScanSource& source, const SlamRunResult& result,
                                    eval::AlignmentMode alignment, double max_time_gap_s);

// How far the corrected trajectory lies from the odometry at the same stamps (positions; the
// world frame is the odometry frame of the first submap).
struct TrajectoryShift {
  double rms_m = 0.0;
  double max_m = 0.0;
};
TrajectoryShift trajectory_shift(const SlamRunResult& result);

// The per-module timing table and the counters, as the runner prints them.
void print_slam_run(const SlamRunResult& result, FILE* out);
// The timeline as a table, one line per sample.
void print_timeline(const std::vector<TimelineSample>& timeline, FILE* out);

// The nearest-rank percentile (0 < percent <= 100) of `values`; NaN when empty. Reorders them.
double nearest_rank_percentile(std::vector<double>* values, double percent);
// VmRSS and VmHWM of /proc/self/status in MB (MiB); NaN when unreadable.
void host_memory_mb(double* rss_mb, double* peak_rss_mb);

}  // namespace tools
}  // namespace covox

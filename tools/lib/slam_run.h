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

// The per-module timing table and the counters, as the runner prints them.
void print_slam_run(const SlamRunResult& result, FILE* out);

// voxgraph's ARCHE configuration on `device`: 0.2 m voxels, 0.6 m truncation, 16 m rays,
// constant weight with drop-off and sparsity compensation 20; then the settings chosen on the
// simulated flight (slam_run.cpp says why): a submap every 5 s (voxgraph: 10 s), odometry sigmas
// 0.07 m and 0.007 rad per submap, a registration accuracy floor of 0.2 m and 1 degree, the
// consistency gate at 0.3 m and the interpolated trajectory correction.
pipeline::SlamConfig arche_slam_config(Device device);
// RGB-D (7-Scenes-sized rooms): inverse-square weighting (depth noise grows with range), no
// sparsity compensation (every pixel hits a surface), 4 cm voxels, 12 cm truncation, 4 m rays,
// a submap every 2 s, odometry sigmas 0.1 m and 0.01 rad.
pipeline::SlamConfig rgbd_slam_config(Device device);
// City-scale LiDAR keyframes (MulRan, ~9 m apart): 0.5 m voxels, 1.5 m truncation, 40 m rays,
// a submap every 8 s (about 10 keyframes).
pipeline::SlamConfig lidar_keyframe_slam_config(Device device);
// "arche", "rgbd" or "lidar-keyframes"; throws covox::Error naming the bad value otherwise.
pipeline::SlamConfig preset_slam_config(const std::string& preset, Device device);

// Applies the SLAM parameters of a flat YAML file (as the nodelet reads them, e.g.
// config/arche.yaml) over `config`; the device stays as it was. Frames, topics and visualisation
// settings are the nodelet's: they are skipped and named in `ignored`. Throws covox::Error for an
// unreadable file or a bad value.
struct ConfigFileUse {
  size_t applied = 0;
  std::string ignored;  // comma-separated names
};
ConfigFileUse apply_slam_config_file(const std::string& path, pipeline::SlamConfig* config);

}  // namespace tools
}  // namespace covox

// run_slam: the offline runner. Feeds a ROS bag (simulate_flight's, an ARCHE flight, or any bag
// with PointCloud2 and tf or Odometry) or a dataset folder (RGB-D or LiDAR keyframes, see
// runner/dataset_scan_sources.h) through the same SlamSystem a robot runs - sensor queue,
// frontend thread building submaps, submap queue, backend thread finishing them, registering
// them and optimising the pose graph - as fast as the machine allows, without ROS. Writes the
// corrected and the odometry trajectories (TUM), the combined mesh (PLY), optionally the map,
// prints a per-module timing table with the real-time factor, and evaluates both trajectories
// against the input's reference (ATE RMSE). With --simulate the scans come from a simulated flight
// generated in process instead (runner/sim_scan_source.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "runner/bag_extrinsic.h"
#include "runner/bag_scan_source.h"
#include "benchmark/benchmark_report.h"
#include "cli/command_line.h"
#include "eval/constraint_evaluation.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/trajectory_io.h"
#include "runner/dataset_scan_sources.h"
#include "eval/png_plot.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "covoxslam/pipeline/submap.h"
#include "runner/sim_scan_source.h"
#include "runner/slam_run.h"
#include "eval/trajectory_evaluation.h"

namespace {

using namespace covox;

// Bounds of the options: a smaller voxel, a longer duration or a larger queue does not fit any
// machine (0.001 m voxels over a flight ask for ~150 GB).
constexpr int64_t kIntMax = tools::CommandLine::kIntMax;
constexpr double kMinVoxelSizeM = 0.005;
constexpr double kMaxDurationS = 86400.0;

const char kUsage[] =
    "usage: run_slam (--bag FILE | --dataset DIR | --simulate) [options]\n"
    "input (default --bag sim_flight/flight.bag):\n"
    "  --bag FILE                  ROS bag (format 2.0; chunks uncompressed, lz4 or bz2)\n"
    "  --cloud-topic T             (default /penguin/os1_cloud_node/points)\n"
    "  --odom-frame F              odometry frame in tf (default odom)\n"
    "  --odometry-topic T          take odometry from nav_msgs/Odometry on T instead of tf\n"
    "  --reference-topic T         PointStamped or Odometry reference (default "
    "/penguin/piksi_node/enu_pose_fix)\n"
    "  --sensor-frame F            frame of the clouds (default: each cloud's frame_id)\n"
    "  --extrinsic \"x y z qx qy qz qw\"\n"
    "                              the clouds' frame in the base frame (metres, unit\n"
    "                              quaternion, as ros.T_base_sensor; or 16 numbers, a\n"
    "                              row-major 4x4) instead of the bag's tf from the base frame\n"
    "                              (default: ros.T_base_sensor of the config where it sets\n"
    "                              ros.use_tf_for_extrinsic: false)\n"
    "  --base-frame F              the frame the odometry moves and --extrinsic starts from\n"
    "                              (default: the config's ros.base_frame, e.g. imu for arche)\n"
    "  --min-range-m R             drop points nearer than R (default 0.5: the drone itself)\n"
    "  --dataset DIR               RGB-D folder (7-Scenes, 3DMatch, Replica) or LiDAR keyframes "
    "(MulRan layout)\n"
    "  --pixel-stride N            RGB-D: every N-th pixel (default 2)\n"
    "  --frame-rate-hz F           RGB-D: frame rate for stamps (default 30)\n"
    "  --drift-m D                 RGB-D: least final odometry drift (default 0.3)\n"
    "  --drift-seed N              RGB-D, keyframe graphs, --added-drift-m: drift seed (default "
    "1)\n"
    "  --drift-scale S             RGB-D and keyframe graphs: drift model and least drift times S\n"
    "                              (default 1; 0: odometry = reference)\n"
    "  --keyframe-drift-m D        keyframe graphs (graph.txt): least final odometry drift "
    "(default "
    "0.3)\n"
    "  --added-drift-m D           LiDAR keyframes (MulRan layout): add the simulator's drift to\n"
    "                              the recorded odometry, at least D m at the end (default 0:\n"
    "                              the odometry as recorded)\n"
    "  --max-scans N               stop after N scans (0: all)\n"
    "  --simulate                  a simulated flight generated scan by scan in process, no bag\n"
    "                              (simulate_flight's scans for the same options; --min-range-m\n"
    "                              applies); the simulator's options are listed at the end\n"
    "mapping (defaults from the preset; each option below overrides it):\n"
    "  --device auto|cpu|cuda      (default auto)\n"
    "  --preset NAME               a configuration file in config/ (COVOX_CONFIG_DIR) with the\n"
    "                              sensor's facts: arche (the default for bags and --simulate),\n"
    "                              rgbd (the default for RGB-D folders), lidar_keyframes (the\n"
    "                              default for keyframe folders); docs/parameters.md lists them\n"
    "  --config FILE.yaml          a configuration file applied over the preset (of its `ros`\n"
    "                              section, the nodelet's, only the extrinsic keys are read)\n"
    "  --voxel-size-m S            voxel size\n"
    "  --truncation-m T            truncation distance\n"
    "  --max-ray-m R               points farther only clear space\n"
    "  --submap-policy time|distance|blocks\n"
    "  --submap-interval-s S       time policy: seconds per submap\n"
    "  --submap-distance-m D       distance policy: metres of path per submap\n"
    "  --submap-max-blocks N       blocks policy: blocks per submap\n"
    "  --sensor-queue N            sensor queue size in scans\n"
    "  --submap-queue N            submap queue size in submaps\n"
    "output:\n"
    "  --trajectory FILE.tum       corrected trajectory (default run_slam_trajectory.tum)\n"
    "  --odometry-trajectory FILE  odometry trajectory of the same scans (default: not written)\n"
    "  --reference-trajectory FILE the input's reference trajectory (default: not written)\n"
    "  --mesh FILE.ply             combined mesh (default run_slam_mesh.ply)\n"
    "  --graph FILE.txt            submaps and pose-graph constraints as text (default: not "
    "written):\n"
    "                              'submap ID START_S END_S x y z yaw (corrected) x y z yaw "
    "(odometry)',\n"
    "                              'constraint KIND FROM TO dx dy dz dyaw', the information's "
    "diagonal\n"
    "                              and 1 (0: set aside by the consistency gate)\n"
    "  --map FILE                  also save the map (default: not saved)\n"
    "  --align none|translation|4dof|se3|sim3  ATE alignment (default 4dof: translation + yaw, as "
    "ARCHE)\n"
    "  --max-time-gap-s G          association tolerance (default 0.1)\n"
    "  --verify-constraints        print each registration constraint's error against the "
    "reference\n"
    "  --verify-tolerance-m M      ... and count those wrong by more than M (default 0.1) or 2 "
    "degrees\n"
    "  --debug-log                 the library's debug lines (each registration's statistics)\n"
    "  --json FILE                 write the results as a benchmark report (e.g. "
    "docs/benchmarks/pipeline.json)\n"
    "  --case NAME                 the report's case name (default: the input's file name)\n"
    "  --timeline-interval-s S     a mission timeline sample every S s of sensor time (default "
    "30;\n"
    "                              0: none): memory, map blocks, scan-time percentiles and\n"
    "                              per-submap registration and solve times, printed and in the\n"
    "                              report as cases t=NNNNs\n"
    "  --timeline-plot FILE.png    the timeline as a plot: memory, scan times and per-submap\n"
    "                              times against mission time\n"
    "  --quiet                     no progress bar\n"
    "simulator (with --simulate; --drift-scale then scales the simulated odometry's drift):\n";

// The final pose graph as text, for inspection: one line per submap and per constraint (m, rad).
void write_graph(const std::string& path, const tools::SlamRunResult& result) {
  io::write_file_replacing(path, "run_slam --graph", /*binary=*/false, [&](std::ostream& file) {
    char line[512];
    for (const pipeline::SubmapInfo& submap : result.submaps) {
      const backend::Pose4Dof world = pipeline::pose_4dof_from_isometry(submap.T_world_submap);
      const backend::Pose4Dof odom = pipeline::pose_4dof_from_isometry(submap.T_odom_submap);
      std::snprintf(line, sizeof(line),
                    "submap %lld %.6f %.6f %.6f %.6f %.6f %.8f %.6f %.6f %.6f %.8f\n",
                    static_cast<long long>(submap.id), submap.statistics.start_stamp_s,
                    submap.statistics.end_stamp_s, world.x, world.y, world.z, world.yaw, odom.x,
                    odom.y, odom.z, odom.yaw);
      file << line;
    }
    for (const pipeline::SubmapConstraint& c : result.constraints) {
      std::snprintf(line, sizeof(line),
                    "constraint %s %lld %lld %.6f %.6f %.6f %.8f %.6g %.6g %.6g %.6g %d\n",
                    pipeline::to_string(c.kind), static_cast<long long>(c.from_submap),
                    static_cast<long long>(c.to_submap), c.measurement.x, c.measurement.y,
                    c.measurement.z, c.measurement.yaw, c.information(0, 0), c.information(1, 1),
                    c.information(2, 2), c.information(3, 3), c.active ? 1 : 0);
      file << line;
    }
  });
}

void add_timing_rows(tools::BenchmarkReport* report, const std::string& name,
                     const std::string& module, const pipeline::ModuleTiming& timing) {
  report->add(name, module + " total", timing.total_s, "s");
  report->add(name, module + " mean", timing.mean_ms(), "ms");
  report->add(name, module + " calls", static_cast<double>(timing.calls), "");
}

// The command line, read once.
struct RunnerSettings {
  std::string bag_path, dataset_path;
  bool simulate = false;
  sim::SimulationOptions simulation;
  tools::BagScanOptions bag_options;
  std::string base_frame_text, extrinsic_text;  // --base-frame, --extrinsic; empty: not given
  tools::RgbdScanOptions rgbd_options;
  tools::LidarKeyframeScanOptions lidar_options;
  int64_t max_scans = 0;
  std::string device_text, preset, config_path;
  // Overrides of the preset; NaN (numbers) or empty (texts): not given.
  double voxel_size_m, truncation_m, max_ray_m, interval_s, distance_m, max_blocks;
  double sensor_queue, submap_queue;
  std::string policy_text;
  std::string trajectory_path, odometry_path, reference_path, mesh_path, graph_path, map_path;
  std::string align_text, json_path, case_name, timeline_plot_path;
  double timeline_interval_s = 30.0;
  double max_time_gap_s = 0.1;
  bool quiet = false;
  bool verify_constraints = false;
  double verify_tolerance_m = 0.1;
  bool debug_log = false;
};

void read_input_options(tools::CommandLine& args, RunnerSettings* s) {
  s->bag_path = args.text("--bag", "");
  s->dataset_path = args.text("--dataset", "");
  tools::BagScanOptions& bag = s->bag_options;
  bag.cloud_topic = args.text("--cloud-topic", bag.cloud_topic);
  bag.odom_frame = args.text("--odom-frame", bag.odom_frame);
  bag.odometry_topic = args.text("--odometry-topic", bag.odometry_topic);
  bag.reference_topic = args.text("--reference-topic", bag.reference_topic);
  bag.sensor_frame = args.text("--sensor-frame", bag.sensor_frame);
  bag.min_range_m = args.number("--min-range-m", 0.5, 0.0, 1000.0);
  s->base_frame_text = args.text("--base-frame", "");
  s->extrinsic_text = args.text("--extrinsic", "");
  tools::RgbdScanOptions& rgbd = s->rgbd_options;
  rgbd.pixel_stride = static_cast<int>(args.integer("--pixel-stride", rgbd.pixel_stride, 1, 64));
  rgbd.frame_rate_hz = args.number("--frame-rate-hz", rgbd.frame_rate_hz, 0.01, 10000.0);
  rgbd.min_final_drift_m = args.number("--drift-m", rgbd.min_final_drift_m, 0.0, 10000.0);
  rgbd.drift_seed = static_cast<uint64_t>(
      args.integer("--drift-seed", 1, 0, std::numeric_limits<int64_t>::max()));
  rgbd.drift_scale = args.number("--drift-scale", rgbd.drift_scale, 0.0, 1000.0);
  s->lidar_options.min_final_drift_m = args.number("--keyframe-drift-m", 0.3, 0.0, 10000.0);
  s->lidar_options.drift_seed = rgbd.drift_seed;
  s->lidar_options.drift_scale = rgbd.drift_scale;
  s->lidar_options.added_drift_m = args.number("--added-drift-m", 0.0, 0.0, 10000.0);
  s->max_scans = args.integer("--max-scans", 0, 0, kIntMax);
  s->simulate = args.flag("--simulate");
  if (s->simulate) s->simulation = sim::read_simulation_options(args);
  if ((s->simulate || !s->dataset_path.empty()) &&
      !(s->base_frame_text + s->extrinsic_text).empty())
    args.fail("--extrinsic and --base-frame apply to --bag only");
}

void read_mapping_options(tools::CommandLine& args, RunnerSettings* s) {
  const double unset = std::numeric_limits<double>::quiet_NaN();
  s->device_text = args.text("--device", "auto");
  s->preset = args.text("--preset", "");
  s->config_path = args.text("--config", "");
  s->voxel_size_m = args.number("--voxel-size-m", unset, kMinVoxelSizeM, 10.0);
  s->truncation_m = args.number("--truncation-m", unset, kMinVoxelSizeM, 100.0);
  s->max_ray_m = args.number("--max-ray-m", unset, 0.1, 1000.0);
  s->policy_text = args.text("--submap-policy", "");
  s->interval_s = args.number("--submap-interval-s", unset, 0.01, kMaxDurationS);
  s->distance_m = args.number("--submap-distance-m", unset, 0.01, 100000.0);
  s->max_blocks = args.number("--submap-max-blocks", unset, 1.0, 1e8);
  s->sensor_queue = args.number("--sensor-queue", unset, 1.0, 100000.0);
  s->submap_queue = args.number("--submap-queue", unset, 1.0, 1000.0);
}

void read_output_options(tools::CommandLine& args, RunnerSettings* s) {
  s->trajectory_path = args.output_file("--trajectory", "run_slam_trajectory.tum");
  s->odometry_path = args.output_file("--odometry-trajectory", "");
  s->reference_path = args.output_file("--reference-trajectory", "");
  s->mesh_path = args.output_file("--mesh", "run_slam_mesh.ply");
  s->graph_path = args.output_file("--graph", "");
  s->map_path = args.output_file("--map", "");
  s->align_text = args.text("--align", "4dof");
  s->max_time_gap_s = args.number("--max-time-gap-s", 0.1, 0.0, kMaxDurationS);
  s->json_path = args.output_file("--json", "");
  s->case_name = args.text("--case", "");
  s->timeline_interval_s =
      args.number("--timeline-interval-s", s->timeline_interval_s, 0.0, kMaxDurationS);
  s->timeline_plot_path = args.output_file("--timeline-plot", "");
  s->quiet = args.flag("--quiet");
  s->verify_constraints = args.flag("--verify-constraints");
  s->verify_tolerance_m = args.number("--verify-tolerance-m", s->verify_tolerance_m, 0.0, 1000.0);
  s->debug_log = args.flag("--debug-log");
}

// --config is read when the configuration is built (after the input is opened): a folder or a
// typo ends the run here instead.
void check_config_file(const tools::CommandLine& args, const std::string& path) {
  if (path.empty()) return;
  try {
    io::read_text_file(path);
  } catch (const Error& error) {
    args.fail(std::string("--config: ") + error.what());
  }
}

RunnerSettings read_settings(tools::CommandLine& args) {
  RunnerSettings s;
  read_input_options(args, &s);
  read_mapping_options(args, &s);
  read_output_options(args, &s);
  args.finish();
  check_config_file(args, s.config_path);
  if (int(!s.bag_path.empty()) + int(!s.dataset_path.empty()) + int(s.simulate) > 1)
    args.fail("give one of --bag, --dataset and --simulate");
  if (s.bag_path.empty() && s.dataset_path.empty() && !s.simulate)
    s.bag_path = "sim_flight/flight.bag";
  if (s.max_scans < 0) args.fail("--max-scans must be >= 0");
  if (!(s.timeline_interval_s >= 0.0)) args.fail("--timeline-interval-s must be >= 0");
  if (!s.timeline_plot_path.empty() && !(s.timeline_interval_s > 0.0))
    args.fail("--timeline-plot needs --timeline-interval-s > 0");
  for (const double count : {s.max_blocks, s.sensor_queue, s.submap_queue}) {
    if (!std::isnan(count) && !(count >= 1.0 && count == std::floor(count))) {
      args.fail("--submap-max-blocks, --sensor-queue and --submap-queue take integers >= 1");
    }
  }
  if (s.case_name.empty() && s.simulate) s.case_name = "simulated";
  if (s.case_name.empty()) {
    const std::string input = s.bag_path.empty() ? s.dataset_path : s.bag_path;
    const size_t slash = input.find_last_of('/', input.size() > 1 ? input.size() - 2 : 0);
    s.case_name = slash == std::string::npos ? input : input.substr(slash + 1);
  }
  return s;
}

std::unique_ptr<tools::ScanSource> open_source(RunnerSettings& s) {
  if (s.simulate) {
    return std::make_unique<tools::SimScanSource>(s.simulation, s.bag_options.min_range_m,
                                                  static_cast<size_t>(s.max_scans));
  }
  if (!s.bag_path.empty()) {
    // The extrinsic is read from the same configuration files as the mapping parameters.
    if (s.preset.empty()) s.preset = "arche";
    std::vector<std::string> config_paths = {pipeline::preset_path(s.preset)};
    if (!s.config_path.empty()) config_paths.push_back(s.config_path);
    tools::resolve_bag_extrinsic(config_paths, s.base_frame_text, s.extrinsic_text, &s.bag_options);
    return std::make_unique<tools::BagScanSource>(s.bag_path, s.bag_options);
  }
  if (s.max_scans > 0) {
    s.rgbd_options.max_frames = s.lidar_options.max_scans = static_cast<size_t>(s.max_scans);
  }
  return tools::open_dataset_scan_source(s.dataset_path, s.rgbd_options, s.lidar_options);
}

// The preset (chosen by the input's kind unless given), the --config file over it, then the
// command line's overrides.
pipeline::SlamConfig build_config(RunnerSettings& s, const tools::ScanSource& source,
                                  Device device) {
  if (s.preset.empty()) s.preset = tools::default_preset(source);
  pipeline::SlamConfig config = pipeline::load_preset(s.preset);
  if (!s.config_path.empty()) {
    const pipeline::SlamConfigFileUse use = pipeline::load_slam_config(s.config_path, &config);
    std::printf("config: %s (%zu SLAM parameters, %zu of the nodelet's ignored)\n",
                s.config_path.c_str(), use.applied, use.node_keys.size());
  }
  config.device = device;
  if (!std::isnan(s.voxel_size_m)) config.map.voxel_size_m = static_cast<float>(s.voxel_size_m);
  if (!std::isnan(s.truncation_m))
    config.tsdf.truncation_distance_m = static_cast<float>(s.truncation_m);
  if (!std::isnan(s.max_ray_m)) config.tsdf.max_ray_length_m = static_cast<float>(s.max_ray_m);
  if (!s.policy_text.empty())
    config.submaps.policy = pipeline::parse_submap_creation_policy(s.policy_text);
  if (!std::isnan(s.interval_s)) config.submaps.interval_s = s.interval_s;
  if (!std::isnan(s.distance_m)) config.submaps.distance_m = s.distance_m;
  if (!std::isnan(s.max_blocks)) config.submaps.max_blocks = static_cast<int64_t>(s.max_blocks);
  if (!std::isnan(s.sensor_queue)) config.sensor_queue_size = static_cast<size_t>(s.sensor_queue);
  if (!std::isnan(s.submap_queue)) config.submap_queue_size = static_cast<size_t>(s.submap_queue);
  pipeline::validate(config);
  return config;
}

void write_outputs(const RunnerSettings& s, const tools::ScanSource& source,
                   const tools::SlamRunResult& result) {
  io::write_tum_trajectory(s.trajectory_path, result.corrected);
  if (!s.odometry_path.empty()) io::write_tum_trajectory(s.odometry_path, result.odometry);
  if (!s.reference_path.empty() && !source.reference().empty())
    io::write_tum_trajectory(s.reference_path, source.reference());
  io::write_mesh_ply(s.mesh_path, result.mesh);
  if (!s.graph_path.empty()) write_graph(s.graph_path, result);
}

void print_evaluation(const tools::SlamRunEvaluation& evaluation, bool truth,
                      eval::AlignmentMode alignment) {
  if (!evaluation.available) {
    std::printf("\nno trajectory evaluation: %s\n", evaluation.problem.c_str());
    return;
  }
  std::printf("\n%s (%s alignment, %zu poses):\n",
              truth ? "ATE RMSE against the ground truth"
                    : "distance to the reference (another estimate, not truth)",
              eval::alignment_mode_name(alignment).c_str(), evaluation.corrected.aligned.size());
  std::printf("  odometry alone   %.3f m RMSE (max %.3f m)\n",
              evaluation.odometry.absolute_position_m.rmse,
              evaluation.odometry.absolute_position_m.max);
  std::printf("  covoxslam        %.3f m RMSE (max %.3f m)\n",
              evaluation.corrected.absolute_position_m.rmse,
              evaluation.corrected.absolute_position_m.max);
}

// What the backend did: registrations by outcome and the trajectory's shift from the odometry.
void add_backend_rows(tools::BenchmarkReport* report, const std::string& name,
                      const tools::SlamRunResult& result) {
  const pipeline::RegistrationCounts& r = result.counters.registration;
  const std::pair<const char*, int64_t> counts[] = {
      {"registrations attempted", r.attempted},
      {"registrations accepted", r.accepted},
      {"registrations rejected: failed", r.rejected_failed},
      {"registrations rejected: too far", r.rejected_too_far},
      {"registrations rejected: too few points", r.rejected_too_few_points},
      {"registrations rejected: misfit", r.rejected_misfit},
      {"registrations rejected: disagree with odometry", r.rejected_by_odometry},
      {"registrations set aside by the gate", result.counters.registrations_set_aside},
      {"place recognition candidates", result.counters.place_recognition.candidates},
      {"place recognition verified", result.counters.place_recognition.verified},
      {"place recognition accepted", result.counters.place_recognition.accepted},
      {"place recognition rejected: descriptor",
       result.counters.place_recognition.rejected_descriptor},
      {"place recognition rejected: overlap", result.counters.place_recognition.rejected_overlap},
      {"place recognition rejected: registration",
       result.counters.place_recognition.verified -
           result.counters.place_recognition.registration.accepted},
      {"place recognition rejected: unconfirmed", result.counters.place_recognition.unconfirmed}};
  for (const auto& count : counts)
    report->add(name, count.first, static_cast<double>(count.second), "");
  const tools::TrajectoryShift shift = tools::trajectory_shift(result);
  report->add(name, "shift from odometry RMS", shift.rms_m, "m");
  report->add(name, "shift from odometry max", shift.max_m, "m");
}

// Where the finished submaps' voxels ended up under the memory budget, and what moving them cost.
void add_memory_rows(tools::BenchmarkReport* report, const std::string& name,
                     const pipeline::SubmapStoreCounters& m) {
  const double mb = 1024.0 * 1024.0;
  report->add(name, "submaps resident", static_cast<double>(m.submaps_resident), "");
  report->add(name, "submaps compact", static_cast<double>(m.submaps_compact), "");
  report->add(name, "submaps on disk", static_cast<double>(m.submaps_on_disk), "");
  report->add(name, "resident submap memory", static_cast<double>(m.resident_bytes) / mb, "MB");
  report->add(name, "peak resident submap memory", static_cast<double>(m.peak_resident_bytes) / mb,
              "MB");
  report->add(name, "compact submap memory", static_cast<double>(m.compact_bytes) / mb, "MB");
  report->add(name, "spilled submap bytes", static_cast<double>(m.disk_bytes) / mb, "MB");
  report->add(name, "submap mesh memory", static_cast<double>(m.mesh_bytes) / mb, "MB");
  report->add(name, "submap compactions", static_cast<double>(m.compactions), "");
  report->add(name, "submap restores", static_cast<double>(m.restores), "");
  report->add(name, "submap restore time", m.restore_s, "s");
  report->add(name, "submap spills", static_cast<double>(m.spills), "");
  report->add(name, "submap spill reads", static_cast<double>(m.spill_reads), "");
  report->add(name, "submap spill failures", static_cast<double>(m.spill_failures), "");
}

// The timeline as report rows: one case per sample, named by its mission time ("t=0030s"; the
// sample after finish() "t=0200s end"), after the summary case, which readers that take a
// report's first case keep finding.
void add_timeline_rows(tools::BenchmarkReport* report,
                       const std::vector<tools::TimelineSample>& timeline) {
  for (const tools::TimelineSample& t : timeline) {
    char name[32];
    std::snprintf(name, sizeof(name), "t=%04.0fs%s", t.mission_s, t.end ? " end" : "");
    report->add(name, "mission time", t.mission_s, "s");
    report->add(name, "wall time", t.wall_s, "s");
    report->add(name, "host RSS", t.host_rss_mb, "MB");
    report->add(name, "host peak RSS", t.host_peak_rss_mb, "MB");
    if (std::isfinite(t.device_used_mb))
      report->add(name, "device memory used", t.device_used_mb, "MB");
    report->add(name, "map blocks", static_cast<double>(t.map_blocks), "");
    report->add(name, "map memory", t.map_memory_mb, "MB");
    report->add(name, "submaps", static_cast<double>(t.submaps), "");
    report->add(name, "window scans", static_cast<double>(t.window_scans), "");
    if (t.window_scans > 0) {  // a window without scans has no percentiles
      report->add(name, "scan time p50", t.scan_p50_ms, "ms");
      report->add(name, "scan time p95", t.scan_p95_ms, "ms");
      report->add(name, "scan time max", t.scan_max_ms, "ms");
    }
    report->add(name, "window submaps", static_cast<double>(t.window_submaps), "");
    report->add(name, "registration per submap", t.registration_ms_per_submap, "ms");
    report->add(name, "solve per submap", t.solve_ms_per_submap, "ms");
    report->add(name, "window optimisations", static_cast<double>(t.window_optimizations), "");
    report->add(name, "partners per submap", t.partners_per_submap, "");
    report->add(name, "restores per submap", t.restores_per_submap, "");
  }
}

// Memory, scan times and per-submap times against mission time, three panels.
void write_timeline_plot(const std::string& path,
                         const std::vector<tools::TimelineSample>& timeline) {
  using Field = double tools::TimelineSample::*;
  auto series = [&](const char* label, size_t colour, Field field) {
    eval::PlotSeries line;
    line.label = label;
    line.colour = eval::series_colour(colour);
    // The sample after finish() is left out: its window is the flush and the final solve.
    for (const tools::TimelineSample& t : timeline)
      if (!t.end) line.points.push_back(eval::PlotPoint{t.mission_s, t.*field});
    return line;
  };
  std::vector<eval::PlotPanel> panels(3);
  panels[0].title = "MEMORY (MB) OVER MISSION TIME (S)";
  panels[0].series = {series("host RSS", 0, &tools::TimelineSample::host_rss_mb),
                      series("map voxels", 1, &tools::TimelineSample::map_memory_mb)};
  if (!timeline.empty() && std::isfinite(timeline.back().device_used_mb))
    panels[0].series.push_back(series("GPU used", 2, &tools::TimelineSample::device_used_mb));
  panels[1].title = "SCAN TIME (MS): P50, P95, MAX PER WINDOW";
  panels[1].series = {series("p50", 0, &tools::TimelineSample::scan_p50_ms),
                      series("p95", 1, &tools::TimelineSample::scan_p95_ms),
                      series("max", 2, &tools::TimelineSample::scan_max_ms)};
  panels[2].title = "PER SUBMAP (MS): REGISTRATION, POSE-GRAPH SOLVE";
  panels[2].series = {series("registration", 0, &tools::TimelineSample::registration_ms_per_submap),
                      series("solve", 1, &tools::TimelineSample::solve_ms_per_submap)};
  eval::write_png(path, eval::render_stacked_panels(panels));
  std::printf("timeline plot -> %s\n", path.c_str());
}

void write_report(const RunnerSettings& s, const pipeline::SlamConfig& config, int argc,
                  char** argv, const tools::SlamRunResult& result,
                  const tools::SlamRunEvaluation& evaluation, bool truth) {
  const std::string& name = s.case_name;
  tools::BenchmarkReport report("pipeline", describe_device(config.device), argc, argv);
  report.add(name, "scans", static_cast<double>(result.scans_given), "");
  report.add(name, "input duration", result.input_duration_s, "s");
  report.add(name, "wall time", result.wall_s, "s");
  report.add(name, "real-time factor", result.real_time_factor(), "x");
  add_timing_rows(&report, name, "tsdf", result.timings.tsdf);
  add_timing_rows(&report, name, "esdf", result.timings.esdf);
  add_timing_rows(&report, name, "mesh", result.timings.mesh);
  add_timing_rows(&report, name, "registration", result.timings.registration);
  add_timing_rows(&report, name, "backend", result.timings.backend);
  add_timing_rows(&report, name, "sensor queue wait", result.timings.sensor_queue_wait);
  add_timing_rows(&report, name, "submap queue wait", result.timings.submap_queue_wait);
  report.add(name, "read input", result.read_s, "s");
  report.add(name, "submaps", static_cast<double>(result.submaps.size()), "");
  add_backend_rows(&report, name, result);
  report.add(name, "map blocks", static_cast<double>(result.map_blocks), "");
  report.add(name, "map memory", result.map_memory_mb, "MB");
  add_memory_rows(&report, name, result.counters.memory);

  if (!result.timeline.empty())
    report.add(name, "host peak RSS", result.timeline.back().host_peak_rss_mb, "MB");
  if (!s.map_path.empty()) {
    report.add(name, "map file size", result.map_file_mb, "MB");
    report.add(name, "map save time", result.map_save_s, "s");
  }
  report.add(name, "scans de-skewed", static_cast<double>(result.counters.scans_deskewed), "");
  report.add(
      name, "scans dropped",
      static_cast<double>(result.counters.scans_dropped_total() + result.scans_dropped_by_source),
      "");
  if (evaluation.available) {
    const std::string metric = truth ? "ATE RMSE " : "distance to reference RMSE ";
    report.add(name, metric + "odometry", evaluation.odometry.absolute_position_m.rmse, "m");
    report.add(name, metric + "covoxslam", evaluation.corrected.absolute_position_m.rmse, "m");
  }
  add_timeline_rows(&report, result.timeline);
  report.write_json(s.json_path);
  std::printf("report -> %s\n", s.json_path.c_str());
}

// --verify-constraints: the yaw tolerance that goes with --verify-tolerance-m.
constexpr double kVerifyToleranceYawRad = 2.0 * 3.14159265358979323846 / 180.0;

void run(RunnerSettings& s, int argc, char** argv) {
  if (s.debug_log) set_min_log_level(LogLevel::kDebug);
  const eval::AlignmentMode alignment = eval::parse_alignment_mode(s.align_text);
  const Device device = select_device(parse_device_request(s.device_text));
  std::unique_ptr<tools::ScanSource> source = open_source(s);
  const pipeline::SlamConfig config = build_config(s, *source, device);
  if (auto* bag = dynamic_cast<tools::BagScanSource*>(source.get()))
    bag->set_column_sweep_duration_s(config.deskew.sweep_duration_s);
  std::printf(
      "device: %s\ninput: %s\npreset: %s (%.3f m voxels, %.3f m truncation, %.1f m rays, "
      "submaps: %s)\n",
      describe_device(config.device).c_str(), source->describe().c_str(), s.preset.c_str(),
      config.map.voxel_size_m, config.tsdf.truncation_distance_m, config.tsdf.max_ray_length_m,
      pipeline::to_string(config.submaps.policy));
  std::fflush(stdout);

  tools::SlamRunOptions options;
  options.max_scans = static_cast<size_t>(s.max_scans);
  options.progress_bar = !s.quiet;
  options.map_path = s.map_path;
  options.timeline_interval_s = s.timeline_interval_s;
  const tools::SlamRunResult result = tools::run_slam_system(*source, config, options);
  write_outputs(s, *source, result);

  tools::print_slam_run(result, stdout);
  if (const auto* simulated = dynamic_cast<const tools::SimScanSource*>(source.get())) {
    std::printf(
        "simulator: %.2f s generating %zu scans (%.2f ms per scan), part of read input\n",
        simulated->generation_s(), result.scans_given,
        result.scans_given > 0 ? 1000.0 * simulated->generation_s() / result.scans_given : 0.0);
  }
  tools::print_timeline(result.timeline, stdout);
  if (!s.timeline_plot_path.empty()) write_timeline_plot(s.timeline_plot_path, result.timeline);
  // With COVOX_PROFILE_STAGES=1: where each module's time went, stage by stage.
  if (StageProfiler::enabled()) std::printf("\n%s\n", StageProfiler::report().c_str());
  std::printf("mesh -> %s\ntrajectory: %zu poses -> %s\n", s.mesh_path.c_str(),
              result.corrected.size(), s.trajectory_path.c_str());
  if (!s.map_path.empty()) {
    std::printf("map -> %s (%.1f MB, saved in %.2f s)\n", s.map_path.c_str(), result.map_file_mb,
                result.map_save_s);
  }

  const tools::SlamRunEvaluation evaluation =
      tools::evaluate_slam_run(*source, result, alignment, s.max_time_gap_s);
  const bool truth = source->reference_kind() == tools::ReferenceKind::kGroundTruth;
  print_evaluation(evaluation, truth, alignment);
  if (s.verify_constraints && !source->reference().empty()) {
    const eval::ConstraintEvaluation constraints = eval::evaluate_registration_constraints(
        source->reference(), result.submaps, result.constraints, s.verify_tolerance_m,
        kVerifyToleranceYawRad);
    eval::print_constraint_evaluation(constraints, stdout);
  } else if (config.place_recognition.enabled && truth && !source->reference().empty()) {
    // A wrong loop closure bends the whole map: with ground truth, closures are always checked.
    eval::print_closure_evaluation(eval::evaluate_registration_constraints(
                                       source->reference(), result.submaps, result.constraints,
                                       s.verify_tolerance_m, kVerifyToleranceYawRad),
                                   stdout);
  }
  if (!s.json_path.empty()) write_report(s, config, argc, argv, result, evaluation, truth);
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, std::string(kUsage) + sim::kSimulationUsage);
  RunnerSettings settings = read_settings(args);
  try {
    run(settings, argc, argv);
  } catch (const Error& error) {
    std::cerr << "\nrun_slam: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

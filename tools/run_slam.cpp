// run_slam: the offline runner. Feeds a ROS bag (simulate_flight's, an ARCHE flight, or any bag
// with PointCloud2 and tf or Odometry) or a dataset folder (RGB-D or LiDAR keyframes, see
// tools/lib/dataset_scan_sources.h) through the same SlamSystem a robot runs - sensor queue,
// frontend thread building submaps, submap queue, backend thread finishing them, registering
// them and optimising the pose graph - as fast as the machine allows, without ROS. Writes the
// corrected and the odometry trajectories (TUM), the combined mesh (PLY), optionally the map,
// prints a per-module timing table with the real-time factor, and evaluates both trajectories
// against the input's reference (ATE RMSE).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <iostream>
#include <memory>
#include <string>

#include "bag_scan_source.h"
#include "benchmark_report.h"
#include "command_line.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/trajectory_io.h"
#include "dataset_scan_sources.h"
#include "flat_yaml.h"
#include "covoxslam/pipeline/slam_parameters.h"
#include "covoxslam/pipeline/submap.h"
#include "slam_run.h"
#include "trajectory_evaluation.h"

namespace {

using namespace covox;

const char kUsage[] =
    "usage: run_slam (--bag FILE | --dataset DIR) [options]\n"
    "input (default --bag sim_flight/flight.bag):\n"
    "  --bag FILE                  ROS bag (format 2.0, uncompressed chunks)\n"
    "  --cloud-topic T             (default /penguin/os1_cloud_node/points)\n"
    "  --odom-frame F              odometry frame in tf (default odom)\n"
    "  --odometry-topic T          take odometry from nav_msgs/Odometry on T instead of tf\n"
    "  --reference-topic T         PointStamped or Odometry reference (default "
    "/penguin/piksi_node/enu_pose_fix)\n"
    "  --sensor-frame F            frame of the clouds (default: each cloud's frame_id)\n"
    "  --min-range-m R             drop points nearer than R (default 0.5: the drone itself)\n"
    "  --dataset DIR               RGB-D folder (7-Scenes, 3DMatch, Replica) or LiDAR keyframes "
    "(MulRan layout)\n"
    "  --pixel-stride N            RGB-D: every N-th pixel (default 2)\n"
    "  --frame-rate-hz F           RGB-D: frame rate for stamps (default 30)\n"
    "  --drift-m D                 RGB-D: least final odometry drift (default 0.3)\n"
    "  --drift-seed N              RGB-D: drift seed (default 1)\n"
    "  --max-scans N               stop after N scans (0: all)\n"
    "mapping (defaults from the preset):\n"
    "  --device auto|cpu|cuda      (default auto)\n"
    "  --preset NAME               arche (bags: 0.2 m voxels, 0.6 m truncation, 16 m rays, LiDAR "
    "weighting,\n"
    "                              5 s submaps), rgbd (RGB-D folders: 4 cm, 12 cm, 4 m, "
    "inverse-square\n"
    "                              weighting, 2 s), lidar-keyframes (keyframe folders: 0.5 m, 1.5 "
    "m, 40 m, 8 s)\n"
    "  --config FILE.yaml          SLAM parameters as the nodelet reads them (e.g. "
    "config/arche.yaml),\n"
    "                              applied over the preset; ROS-only parameters in it are ignored\n"
    "  --voxel-size-m S            voxel size\n"
    "  --truncation-m T            truncation distance\n"
    "  --max-ray-m R               points farther only clear space\n"
    "  --submap-policy time|distance|blocks  (default time, voxgraph's)\n"
    "  --submap-interval-s S       time policy: seconds per submap\n"
    "  --submap-distance-m D       distance policy: metres of path per submap (default 20)\n"
    "  --submap-max-blocks N       blocks policy: blocks per submap (default 1000)\n"
    "  --sensor-queue N            sensor queue size in scans (default 20)\n"
    "  --submap-queue N            submap queue size in submaps (default 4)\n"
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
    "  --json FILE                 write the results as a benchmark report (e.g. "
    "docs/benchmarks/pipeline.json)\n"
    "  --case NAME                 the report's case name (default: the input's file name)\n"
    "  --quiet                     no progress bar\n";

// The final pose graph as text, for inspection: one line per submap and per constraint (m, rad).
void write_graph(const std::string& path, const tools::SlamRunResult& result) {
  FILE* file = std::fopen(path.c_str(), "w");
  if (!file) throw Error("run_slam: cannot write " + path);
  for (const pipeline::SubmapInfo& submap : result.submaps) {
    const backend::Pose4Dof world = pipeline::pose_4dof_from_isometry(submap.T_world_submap);
    const backend::Pose4Dof odom = pipeline::pose_4dof_from_isometry(submap.T_odom_submap);
    std::fprintf(file, "submap %lld %.6f %.6f %.6f %.6f %.6f %.8f %.6f %.6f %.6f %.8f\n",
                 static_cast<long long>(submap.id), submap.statistics.start_stamp_s,
                 submap.statistics.end_stamp_s, world.x, world.y, world.z, world.yaw, odom.x,
                 odom.y, odom.z, odom.yaw);
  }
  for (const pipeline::SubmapConstraint& c : result.constraints) {
    std::fprintf(file, "constraint %s %lld %lld %.6f %.6f %.6f %.8f %.6g %.6g %.6g %.6g %d\n",
                 pipeline::to_string(c.kind), static_cast<long long>(c.from_submap),
                 static_cast<long long>(c.to_submap), c.measurement.x, c.measurement.y,
                 c.measurement.z, c.measurement.yaw, c.information(0, 0), c.information(1, 1),
                 c.information(2, 2), c.information(3, 3), c.active ? 1 : 0);
  }
  std::fclose(file);
}

void add_timing_rows(tools::BenchmarkReport* report, const std::string& name,
                     const std::string& module, const pipeline::ModuleTiming& timing) {
  report->add(name, module + " total", timing.total_s, "s");
  report->add(name, module + " mean", timing.mean_ms(), "ms");
  report->add(name, module + " calls", static_cast<double>(timing.calls), "");
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  std::string bag_path = args.text("--bag", "");
  const std::string dataset_path = args.text("--dataset", "");
  tools::BagScanOptions bag_options;
  bag_options.cloud_topic = args.text("--cloud-topic", bag_options.cloud_topic);
  bag_options.odom_frame = args.text("--odom-frame", bag_options.odom_frame);
  bag_options.odometry_topic = args.text("--odometry-topic", bag_options.odometry_topic);
  bag_options.reference_topic = args.text("--reference-topic", bag_options.reference_topic);
  bag_options.sensor_frame = args.text("--sensor-frame", bag_options.sensor_frame);
  bag_options.min_range_m = args.number("--min-range-m", 0.5);
  tools::RgbdScanOptions rgbd_options;
  rgbd_options.pixel_stride =
      static_cast<int>(args.integer("--pixel-stride", rgbd_options.pixel_stride));
  rgbd_options.frame_rate_hz = args.number("--frame-rate-hz", rgbd_options.frame_rate_hz);
  rgbd_options.min_final_drift_m = args.number("--drift-m", rgbd_options.min_final_drift_m);
  rgbd_options.drift_seed = static_cast<uint64_t>(args.integer("--drift-seed", 1));
  tools::LidarKeyframeScanOptions lidar_options;
  const int64_t max_scans = args.integer("--max-scans", 0);
  const std::string device_text = args.text("--device", "auto");
  std::string preset = args.text("--preset", "");
  const std::string config_path = args.text("--config", "");
  // NaN: not given, the preset decides.
  const double unset = std::numeric_limits<double>::quiet_NaN();
  const double voxel_size_m = args.number("--voxel-size-m", unset);
  const double truncation_m = args.number("--truncation-m", unset);
  const double max_ray_m = args.number("--max-ray-m", unset);
  const std::string policy_text = args.text("--submap-policy", "time");
  const double interval_s = args.number("--submap-interval-s", unset);
  const double distance_m = args.number("--submap-distance-m", 20.0);
  const int64_t max_blocks = args.integer("--submap-max-blocks", 1000);
  const int64_t sensor_queue = args.integer("--sensor-queue", 20);
  const int64_t submap_queue = args.integer("--submap-queue", 4);
  const std::string trajectory_path = args.text("--trajectory", "run_slam_trajectory.tum");
  const std::string odometry_path = args.text("--odometry-trajectory", "");
  const std::string reference_path = args.text("--reference-trajectory", "");
  const std::string mesh_path = args.text("--mesh", "run_slam_mesh.ply");
  const std::string graph_path = args.text("--graph", "");
  const std::string map_path = args.text("--map", "");
  const std::string align_text = args.text("--align", "4dof");
  const double max_time_gap_s = args.number("--max-time-gap-s", 0.1);
  const std::string json_path = args.text("--json", "");
  std::string case_name = args.text("--case", "");
  const bool quiet = args.flag("--quiet");
  args.finish();
  if (!bag_path.empty() && !dataset_path.empty()) args.fail("give --bag or --dataset, not both");
  if (bag_path.empty() && dataset_path.empty()) bag_path = "sim_flight/flight.bag";
  if (max_scans < 0) args.fail("--max-scans must be >= 0");
  if (sensor_queue < 1 || submap_queue < 1)
    args.fail("--sensor-queue and --submap-queue must be at least 1");

  try {
    const tools::AlignmentMode alignment = tools::parse_alignment_mode(align_text);
    const Device device = select_device(parse_device_request(device_text));
    std::unique_ptr<tools::ScanSource> source;
    if (!bag_path.empty()) {
      source = std::make_unique<tools::BagScanSource>(bag_path, bag_options);
    } else {
      if (max_scans > 0)
        rgbd_options.max_frames = lidar_options.max_scans = static_cast<size_t>(max_scans);
      source = tools::open_dataset_scan_source(dataset_path, rgbd_options, lidar_options);
    }
    if (preset.empty()) {
      preset = dynamic_cast<tools::RgbdScanSource*>(source.get())            ? "rgbd"
               : dynamic_cast<tools::LidarKeyframeScanSource*>(source.get()) ? "lidar-keyframes"
                                                                             : "arche";
    }
    pipeline::SlamConfig config = tools::preset_slam_config(preset, device);
    if (!config_path.empty()) {
      const tools::ConfigFileUse use = tools::apply_slam_config_file(config_path, &config);
      std::printf("config: %s (%zu SLAM parameters; not for the runner: %s)\n", config_path.c_str(),
                  use.applied, use.ignored.empty() ? "none" : use.ignored.c_str());
    }
    if (!std::isnan(voxel_size_m)) config.map.voxel_size_m = static_cast<float>(voxel_size_m);
    if (!std::isnan(truncation_m))
      config.tsdf.truncation_distance_m = static_cast<float>(truncation_m);
    if (!std::isnan(max_ray_m)) config.tsdf.max_ray_length_m = static_cast<float>(max_ray_m);
    config.submaps.policy = pipeline::parse_submap_creation_policy(policy_text);
    if (!std::isnan(interval_s)) config.submaps.interval_s = interval_s;
    config.submaps.distance_m = distance_m;
    config.submaps.max_blocks = max_blocks;
    config.sensor_queue_size = static_cast<size_t>(sensor_queue);
    config.submap_queue_size = static_cast<size_t>(submap_queue);
    if (case_name.empty()) {
      const std::string input = bag_path.empty() ? dataset_path : bag_path;
      const size_t slash = input.find_last_of('/', input.size() > 1 ? input.size() - 2 : 0);
      case_name = slash == std::string::npos ? input : input.substr(slash + 1);
    }
    std::printf(
        "device: %s\ninput: %s\npreset: %s (%.3f m voxels, %.3f m truncation, %.1f m rays, "
        "submaps: %s)\n",
        describe_device(config.device).c_str(), source->describe().c_str(), preset.c_str(),
        config.map.voxel_size_m, config.tsdf.truncation_distance_m, config.tsdf.max_ray_length_m,
        pipeline::to_string(config.submaps.policy));
    std::fflush(stdout);

    tools::SlamRunOptions options;
    options.max_scans = static_cast<size_t>(max_scans);
    options.progress_bar = !quiet;
    options.map_path = map_path;
    const tools::SlamRunResult result = tools::run_slam_system(*source, config, options);

    io::write_tum_trajectory(trajectory_path, result.corrected);
    if (!odometry_path.empty()) io::write_tum_trajectory(odometry_path, result.odometry);
    if (!reference_path.empty() && !source->reference().empty())
      io::write_tum_trajectory(reference_path, source->reference());
    io::write_mesh_ply(mesh_path, result.mesh);
    if (!graph_path.empty()) write_graph(graph_path, result);

    tools::print_slam_run(result, stdout);
    // With COVOX_PROFILE_STAGES=1: where each module's time went, stage by stage.
    if (StageProfiler::enabled()) std::printf("\n%s\n", StageProfiler::report().c_str());
    std::printf("mesh -> %s\ntrajectory: %zu poses -> %s\n", mesh_path.c_str(),
                result.corrected.size(), trajectory_path.c_str());
    if (!map_path.empty()) std::printf("map -> %s\n", map_path.c_str());

    const tools::SlamRunEvaluation evaluation =
        tools::evaluate_slam_run(*source, result, alignment, max_time_gap_s);
    const bool truth = source->reference_kind() == tools::ReferenceKind::kGroundTruth;
    if (evaluation.available) {
      std::printf("\n%s (%s alignment, %zu poses):\n",
                  truth ? "ATE RMSE against the ground truth"
                        : "distance to the reference (another estimate, not truth)",
                  tools::alignment_mode_name(alignment).c_str(),
                  evaluation.corrected.aligned.size());
      std::printf("  odometry alone   %.3f m RMSE (max %.3f m)\n",
                  evaluation.odometry.absolute_position_m.rmse,
                  evaluation.odometry.absolute_position_m.max);
      std::printf("  covoxslam        %.3f m RMSE (max %.3f m)\n",
                  evaluation.corrected.absolute_position_m.rmse,
                  evaluation.corrected.absolute_position_m.max);
    } else {
      std::printf("\nno trajectory evaluation: %s\n", evaluation.problem.c_str());
    }

    if (!json_path.empty()) {
      tools::BenchmarkReport report("pipeline", describe_device(config.device), argc, argv);
      report.add(case_name, "scans", static_cast<double>(result.scans_given), "");
      report.add(case_name, "input duration", result.input_duration_s, "s");
      report.add(case_name, "wall time", result.wall_s, "s");
      report.add(case_name, "real-time factor", result.real_time_factor(), "x");
      add_timing_rows(&report, case_name, "tsdf", result.timings.tsdf);
      add_timing_rows(&report, case_name, "esdf", result.timings.esdf);
      add_timing_rows(&report, case_name, "mesh", result.timings.mesh);
      add_timing_rows(&report, case_name, "registration", result.timings.registration);
      add_timing_rows(&report, case_name, "backend", result.timings.backend);
      add_timing_rows(&report, case_name, "sensor queue wait", result.timings.sensor_queue_wait);
      add_timing_rows(&report, case_name, "submap queue wait", result.timings.submap_queue_wait);
      report.add(case_name, "read input", result.read_s, "s");
      report.add(case_name, "submaps", static_cast<double>(result.submaps.size()), "");
      report.add(case_name, "map blocks", static_cast<double>(result.map_blocks), "");
      report.add(case_name, "map memory", result.map_memory_mb, "MB");
      report.add(case_name, "scans dropped",
                 static_cast<double>(result.counters.scans_dropped_total() +
                                     result.scans_dropped_by_source),
                 "");
      if (evaluation.available) {
        const std::string metric = truth ? "ATE RMSE " : "distance to reference RMSE ";
        report.add(case_name, metric + "odometry", evaluation.odometry.absolute_position_m.rmse,
                   "m");
        report.add(case_name, metric + "covoxslam", evaluation.corrected.absolute_position_m.rmse,
                   "m");
      }
      report.write_json(json_path);
      std::printf("report -> %s\n", json_path.c_str());
    }
  } catch (const Error& error) {
    std::cerr << "\nrun_slam: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

#include "slam_run.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

#include "covoxslam/core/error.h"
#include "covoxslam/io/map_file.h"
#include "covoxslam/map/voxels.h"
#include "covoxslam/pipeline/slam_parameters.h"
#include "flat_yaml.h"

namespace covox {
namespace tools {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

void draw_progress(size_t done, size_t total, double elapsed_s, const pipeline::SlamSystem& slam) {
  const int width = 40;
  const double fraction = total > 0 ? std::min(1.0, static_cast<double>(done) / total) : 1.0;
  const int filled = static_cast<int>(fraction * width);
  const double eta_s = done > 0 ? elapsed_s * (total - std::min(done, total)) / done : 0.0;
  std::fprintf(stderr, "\r[%s%s] %3.0f%% scan %zu/%zu, %.0f s, ETA %.0f s, queues %zu/%zu ",
               std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(),
               100.0 * fraction, done, total, elapsed_s, eta_s, slam.sensor_queue_length(),
               slam.submap_queue_length());
}

io::StampedPose to_stamped(double stamp_s, const Eigen::Isometry3d& pose) {
  io::StampedPose stamped;
  stamped.timestamp_s = stamp_s;
  stamped.position_m = pose.translation();
  stamped.orientation = Eigen::Quaterniond(pose.linear()).normalized();
  return stamped;
}

void print_timing(FILE* out, const char* name, const pipeline::ModuleTiming& timing) {
  std::fprintf(out, "%-20s %8lld %10.2f %10.2f %10.2f\n", name,
               static_cast<long long>(timing.calls), timing.total_s, timing.mean_ms(),
               1000.0 * timing.max_s);
}

}  // namespace

pipeline::SlamConfig arche_slam_config(Device device) {
  pipeline::SlamConfig config;
  config.device = device;
  config.map.voxel_size_m = 0.2f;
  config.map.voxels_per_side = 16;
  config.tsdf.truncation_distance_m = 0.6f;
  config.tsdf.max_ray_length_m = 16.0f;
  // Constant weight with drop-off and sparsity compensation, so sparse LiDAR surface hits survive
  // the free-space updates of the many rays that pass them.
  config.tsdf.use_const_weight = true;
  config.tsdf.use_weight_dropoff = true;
  config.tsdf.use_sparsity_compensation_factor = true;
  config.tsdf.sparsity_compensation_factor = 20.0f;
  config.submaps.policy = pipeline::SubmapCreationPolicy::kTimeInterval;
  // 5 s submaps (voxgraph: 10 s): half the odometry drift inside each submap, so registrations
  // compare less distorted maps; with the consistency gate below, the simulated flight over seeds
  // 1/2/3 went from 0.740/0.585/0.344 m to 0.500/0.146/0.385 m (docs/benchmarks.md, "Issue 7,
  // session of 2026-11-24").
  config.submaps.interval_s = 5.0;
  // Registration constraints no surer than registration is at 0.2 m voxels: measured on the
  // simulated flight, 0.24 m and 0.64 degrees from the true relative pose on average
  // (registration_constraints.h; docs/benchmarks.md, "Drift correction on the simulated flight").
  config.registration.min_sigma_m = 0.2;
  config.registration.min_sigma_yaw_rad = 1.0 * 3.14159265358979323846 / 180.0;
  // Symmetric registration (both submaps' points, one solve): on the simulated flight it brought
  // consecutive alignments closer to the true relative pose (0.17 m / 0.58 deg -> 0.14 m / 0.46
  // deg on average) and lowered the ATE on seeds 1 and 2 (docs/benchmarks.md, "Registration
  // accuracy on the simulated flight").
  config.registration.symmetric = true;
  // Revisits start as far off as the odometry drifted since the last one (2.3 to 2.8 m before the
  // last pass of seed 1's flight), and the symmetric aligner reaches them: the 2 m gate of the
  // library rejected those alignments as too far (ATE 0.979 m instead of 0.693 m; seed 2 and
  // 7-Scenes unchanged).
  config.registration.max_correction_m = 3.5;
  // Coarse-to-fine alignment (ESDF every 4, then 2 voxels, then the fine cost): revisits start
  // 2 to 3 m off and the fine cost's basin is a few decimetres. On the simulated flight (256
  // columns, 2-core CPU, 2026-11-23) the ATE over seeds 1/2/3 went from 0.693/0.332/1.160 m to
  // 0.740/0.585/0.344 m (mean 0.728 -> 0.556 m; 3 levels: 0.573 m); docs/benchmarks.md,
  // "Coarse-to-fine registration".
  config.registration.coarse_levels = 2;
  // Revisits start from the walls' match (pipeline/wall_map.h) when it scores 50 or more and lies
  // more than 0.5 m from the guess: registered from 1.5 m off the truth on the zero-drift flight,
  // revisit pairs ended 0.51 m off instead of 1.06 m; over the ten flights (seeds 1-5, 256 and
  // 1024 columns, H100, 2026-11-24) the ATE went from 0.370 m mean / 0.827 m worst to 0.338 /
  // 0.586 m, and on the flight without drift from 0.334 to 0.245 m (docs/benchmarks.md, "Revisits
  // started from the walls").
  config.registration.revisit_wall_search = true;
  // Consistency gate: after each solve, registration constraints more than 0.3 m (horizontal) from
  // the solved relative pose are set aside and the graph solved again. Revisits that landed in a
  // wrong minimum (repeated structure) disagree with the rest by metres.
  config.registration.max_graph_residual_m = 0.3;
  // Worst first: each round of the gate sets aside only the constraints above 0.7 x the largest
  // residual. Setting aside everything above 0.3 m at once lost the right revisits of the last
  // pass with the wrong ones (the wrong ones had pulled the solution, so the right ones disagreed
  // with it too): on seed 1 the active revisits went from 7 to 14. Ten flights (seeds 1-5, 256 and
  // 1024 columns, H100, 2026-11-24): mean ATE 0.338 -> 0.273 m, worst 0.586 -> 0.427 m (fraction
  // 0.3 / 0.5 / 0.9: 0.319 / 0.284 / 0.291 m mean); held-out seeds 6-10 0.585 -> 0.418 m mean
  // (three flights still above 0.5 m); the flight without drift 0.245 -> 0.192 m
  // (docs/benchmarks.md, "The consistency gate, worst first").
  config.registration.gate_worst_fraction = 0.7;
  // The correction of each scan blended in time towards the next submap's (the drift grows inside
  // a submap); the reported trajectory only.
  config.interpolate_trajectory_correction = true;
  // Odometry sigmas per 5 s link: the library's 0.1 m and 0.01 rad were for 10 s; a random walk
  // over half the time has 1/sqrt(2) of the spread (measured on the simulated flight, seed 1:
  // 0.107 m RMS horizontal error per 5 s link, i.e. 0.076 m per axis).
  config.odometry_translation_sigma_m = 0.07;
  config.odometry_yaw_sigma_rad = 0.007;
  // voxgraph's ARCHE information (x, y 1; z, yaw 2500), which config/arche.yaml gives as 1 m /
  // 0.02 rad, lets the registration pull the
  // graph further than max_correction_m allows on the simulated flight (ATE 2.5 m instead of
  // 1.6 m on 2026-11-23); `--config config/arche.yaml` selects it.
  return config;
}

pipeline::SlamConfig rgbd_slam_config(Device device) {
  pipeline::SlamConfig config = arche_slam_config(device);
  config.map.voxel_size_m = 0.04f;
  config.tsdf.truncation_distance_m = 0.12f;
  config.tsdf.max_ray_length_m = 4.0f;
  config.tsdf.use_const_weight = false;
  config.tsdf.use_sparsity_compensation_factor = false;
  config.tsdf.sparsity_compensation_factor = 1.0f;
  config.submaps.interval_s = 2.0;
  // The accuracy floor was measured for 0.2 m LiDAR submaps only.
  config.registration.min_sigma_m = 0.0;
  config.registration.min_sigma_yaw_rad = 0.0;
  // Coarse-to-fine gained nothing on 7-Scenes (0.023 -> 0.024 m): the camera's 2 s submaps start
  // centimetres off, well inside the fine basin.
  config.registration.coarse_levels = 0;
  // A hand-held camera drifts a few centimetres between 2 s submaps.
  config.odometry_translation_sigma_m = 0.1;
  config.odometry_yaw_sigma_rad = 0.01;
  // The consistency gate's 0.3 m and the interpolated correction were measured on the 0.2 m
  // flight only.
  config.registration.max_graph_residual_m = 0.0;
  config.interpolate_trajectory_correction = false;
  return config;
}

pipeline::SlamConfig lidar_keyframe_slam_config(Device device) {
  pipeline::SlamConfig config = arche_slam_config(device);
  config.map.voxel_size_m = 0.5f;
  config.tsdf.truncation_distance_m = 1.5f;
  config.tsdf.max_ray_length_m = 40.0f;
  config.submaps.interval_s = 8.0;
  config.registration.min_sigma_m = 0.0;  // the floor was measured at 0.2 m voxels only
  config.registration.min_sigma_yaw_rad = 0.0;
  config.registration.coarse_levels = 0;  // coarse-to-fine was measured on the 0.2 m flight only
  // The gate, the interpolated correction and the 5 s odometry sigmas likewise (library values).
  config.registration.max_graph_residual_m = 0.0;
  config.interpolate_trajectory_correction = false;
  config.odometry_translation_sigma_m = 0.1;
  config.odometry_yaw_sigma_rad = 0.01;
  return config;
}

pipeline::SlamConfig preset_slam_config(const std::string& preset, Device device) {
  if (preset == "arche") return arche_slam_config(device);
  if (preset == "rgbd") return rgbd_slam_config(device);
  if (preset == "lidar-keyframes") return lidar_keyframe_slam_config(device);
  throw Error("unknown preset '" + preset + "' (arche, rgbd or lidar-keyframes)");
}

SlamRunResult run_slam_system(ScanSource& source, const pipeline::SlamConfig& config,
                              const SlamRunOptions& options) {
  SlamRunResult result;
  const size_t total =
      options.max_scans > 0 ? std::min(options.max_scans, source.size()) : source.size();
  pipeline::SlamSystem slam(config);
  const auto start = Clock::now();
  SourceScan scan;
  double first_stamp_s = 0.0, last_stamp_s = 0.0;
  while (result.scans_given < total) {
    const auto read_start = Clock::now();
    const bool more = source.next(&scan);
    result.read_s += seconds_since(read_start);
    if (!more) break;
    if (result.scans_given == 0) first_stamp_s = scan.stamp_s;
    last_stamp_s = scan.stamp_s;
    result.odometry.poses.push_back(to_stamped(scan.stamp_s, scan.T_odom_sensor));
    // Back-pressure instead of drops. The submap queue keeps one place free for the submap the
    // frontend may be closing right now.
    const auto throttle_start = Clock::now();
    const size_t submap_limit = std::max<size_t>(1, config.submap_queue_size - 1);
    while (slam.sensor_queue_length() >= config.sensor_queue_size ||
           slam.submap_queue_length() >= submap_limit) {
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    result.throttle_s += seconds_since(throttle_start);
    pipeline::Scan input;
    input.stamp_s = scan.stamp_s;
    input.T_odom_sensor = scan.T_odom_sensor;
    input.points_sensor_m = std::move(scan.points_sensor_m);
    input.colors = std::move(scan.colors);
    slam.add_scan(std::move(input));
    ++result.scans_given;
    if (options.progress_bar && (result.scans_given % 10 == 0 || result.scans_given == total)) {
      draw_progress(result.scans_given, total, seconds_since(start), slam);
    }
  }
  const auto finish_start = Clock::now();
  slam.finish();
  result.finish_s = seconds_since(finish_start);
  result.wall_s = seconds_since(start);
  if (options.progress_bar) std::fprintf(stderr, "\n");

  result.scans_dropped_by_source = source.dropped();
  // The input's time span plus one scan period (what a sensor at that rate takes to deliver it).
  result.input_duration_s = source.duration_s();
  if (options.max_scans > 0 || result.input_duration_s <= 0.0) {
    const size_t n = result.scans_given;
    result.input_duration_s = n > 1 ? (last_stamp_s - first_stamp_s) * n / (n - 1) : 0.0;
  }
  for (const pipeline::StampedPose& pose : slam.corrected_trajectory()) {
    result.corrected.poses.push_back(to_stamped(pose.stamp_s, pose.T_world_sensor));
  }
  result.mesh = slam.combined_mesh();
  result.counters = slam.counters();
  result.timings = slam.timings();
  result.submaps = slam.submaps();
  result.constraints = slam.constraints();
  const size_t voxels_per_block = static_cast<size_t>(config.map.voxels_per_side) *
                                  config.map.voxels_per_side * config.map.voxels_per_side;
  for (const pipeline::SubmapInfo& submap : result.submaps)
    result.map_blocks += submap.statistics.blocks;
  result.map_memory_mb = double(result.map_blocks) * voxels_per_block *
                         (sizeof(TsdfVoxel) + sizeof(ColorVoxel) + sizeof(EsdfVoxel)) /
                         (1024.0 * 1024.0);

  if (!options.map_path.empty()) {
    io::MapFileContents contents;
    contents.voxel_size_m = config.map.voxel_size_m;
    contents.voxels_per_side = config.map.voxels_per_side;
    contents.has_esdf = true;  // finishing a submap computes its ESDF
    for (pipeline::SubmapSnapshot& snapshot : slam.submap_snapshots()) {
      io::SubmapRecord record;
      record.id = snapshot.id;
      record.T_world_submap = snapshot.T_world_submap;
      record.blocks = std::move(snapshot.blocks);
      contents.submaps.push_back(std::move(record));
    }
    io::save_map_file(options.map_path, contents);
  }
  return result;
}

SlamRunEvaluation evaluate_slam_run(const ScanSource& source, const SlamRunResult& result,
                                    AlignmentMode alignment, double max_time_gap_s) {
  SlamRunEvaluation evaluation;
  if (source.reference_kind() == ReferenceKind::kNone || source.reference().size() < 3) {
    evaluation.problem = "the input has no reference trajectory";
    return evaluation;
  }
  TrajectoryEvaluationOptions options;
  options.alignment = alignment;
  options.association.max_time_gap_s = max_time_gap_s;
  try {
    evaluation.odometry = evaluate_trajectory(source.reference(), result.odometry, options);
    evaluation.corrected = evaluate_trajectory(source.reference(), result.corrected, options);
    evaluation.available = true;
  } catch (const Error& error) {
    evaluation.problem = error.what();
  }
  return evaluation;
}

void print_slam_run(const SlamRunResult& result, FILE* out) {
  const pipeline::SlamCounters& c = result.counters;
  std::fprintf(
      out,
      "submaps: %lld created, %zu in the pose graph, %lld odometry constraints, registration %lld "
      "accepted of %lld attempted, %lld optimisations\n",
      static_cast<long long>(c.submaps_created), result.submaps.size(),
      static_cast<long long>(c.odometry_constraints),
      static_cast<long long>(c.registration.accepted),
      static_cast<long long>(c.registration.attempted), static_cast<long long>(c.optimizations));
  std::fprintf(out,
               "registration: %lld attempted, %lld accepted, rejected: %lld failed, %lld too far, "
               "%lld too few "
               "points; %lld revisits started from the walls; %lld set aside by the consistency "
               "gate at the end\n",
               static_cast<long long>(c.registration.attempted),
               static_cast<long long>(c.registration.accepted),
               static_cast<long long>(c.registration.rejected_failed),
               static_cast<long long>(c.registration.rejected_too_far),
               static_cast<long long>(c.registration.rejected_too_few_points),
               static_cast<long long>(c.registration.started_from_walls),
               static_cast<long long>(c.registrations_set_aside));
  std::fprintf(out,
               "scans: %zu given, %lld integrated, %lld dropped by the pipeline (queue full %lld, "
               "invalid pose "
               "%lld, empty %lld, bad stamp %lld, failed %lld), %lld dropped while reading; "
               "submaps dropped %lld\n",
               result.scans_given, static_cast<long long>(c.scans_integrated),
               static_cast<long long>(c.scans_dropped_total()),
               static_cast<long long>(c.scans_dropped_queue_full),
               static_cast<long long>(c.scans_dropped_invalid_pose),
               static_cast<long long>(c.scans_dropped_empty_cloud),
               static_cast<long long>(c.scans_dropped_bad_stamp),
               static_cast<long long>(c.scans_failed),
               static_cast<long long>(result.scans_dropped_by_source),
               static_cast<long long>(c.submaps_dropped_queue_full));
  const pipeline::SlamTimings& t = result.timings;
  std::fprintf(out, "\n%-20s %8s %10s %10s %10s\n", "module", "calls", "total s", "mean ms",
               "max ms");
  print_timing(out, "tsdf integrate", t.tsdf);
  print_timing(out, "esdf (submap)", t.esdf);
  print_timing(out, "mesh (submap)", t.mesh);
  print_timing(out, "registration", t.registration);
  print_timing(out, "backend optimise", t.backend);
  print_timing(out, "sensor queue wait", t.sensor_queue_wait);
  print_timing(out, "submap queue wait", t.submap_queue_wait);
  std::fprintf(out, "%-20s %8s %10.2f   (reading and decoding the input)\n", "read input", "",
               result.read_s);
  std::fprintf(out, "%-20s %8s %10.2f   (input held back while a queue was full)\n", "throttle", "",
               result.throttle_s);
  std::fprintf(out, "%-20s %8s %10.2f   (flush and final optimisation)\n", "finish", "",
               result.finish_s);
  std::fprintf(out, "%-20s %8s %10.2f   (%.1f s of input: %.2f x real time)\n", "total wall", "",
               result.wall_s, result.input_duration_s, result.real_time_factor());
  std::fprintf(out, "\nmap: %zu submaps, %zu TSDF blocks (%.1f MB of voxels), mesh %zu triangles\n",
               result.submaps.size(), result.map_blocks, result.map_memory_mb,
               result.mesh.triangle_count());
}

ConfigFileUse apply_slam_config_file(const std::string& path, pipeline::SlamConfig* config) {
  std::map<std::string, std::string> values = read_flat_yaml(path);
  const std::vector<std::string>& known = pipeline::slam_parameter_names();
  ConfigFileUse use;
  for (auto entry = values.begin(); entry != values.end();) {
    if (std::find(known.begin(), known.end(), entry->first) != known.end()) {
      ++entry;
    } else {
      use.ignored += (use.ignored.empty() ? "" : ", ") + entry->first;
      entry = values.erase(entry);
    }
  }
  const Device device = config->device;
  pipeline::read_slam_config(pipeline::TextParameterSource(values), config);
  config->device = device;
  use.applied = values.size();
  return use;
}

}  // namespace tools
}  // namespace covox

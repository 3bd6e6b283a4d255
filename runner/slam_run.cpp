#include "runner/slam_run.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <thread>

#if COVOX_WITH_CUDA
#include <cuda_runtime_api.h>
#endif

#include "covoxslam/core/error.h"
#include "covoxslam/io/map_file.h"
#include "covoxslam/map/voxels.h"

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

void print_timing(FILE* out, const char* name, const pipeline::ModuleTiming& timing) {
  std::fprintf(out, "%-20s %8lld %10.2f %10.2f %10.2f\n", name,
               static_cast<long long>(timing.calls), timing.total_s, timing.mean_ms(),
               1000.0 * timing.max_s);
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The voxel payload of `blocks` TSDF blocks (TSDF, colour and ESDF voxels).
double voxel_memory_mb(size_t blocks, const map::TsdfMapConfig& map) {
  const size_t voxels_per_block =
      static_cast<size_t>(map.voxels_per_side) * map.voxels_per_side * map.voxels_per_side;
  return double(blocks) * voxels_per_block *
         (sizeof(map::TsdfVoxel) + sizeof(map::ColorVoxel) + sizeof(map::EsdfVoxel)) /
         (1024.0 * 1024.0);
}

double device_used_mb(Device device) {
#if COVOX_WITH_CUDA
  size_t free_bytes = 0, total_bytes = 0;
  if (device == Device::kCuda && cudaMemGetInfo(&free_bytes, &total_bytes) == cudaSuccess)
    return double(total_bytes - free_bytes) / (1024.0 * 1024.0);
#else
  (void)device;
#endif
  return kNaN;
}

// Samples the mission every `interval_s` of sensor time. Window figures are differences of the
// system's cumulative timings and counters between two samples, plus the scan times the
// frontend recorded in between (SlamSystem::take_scan_durations).
class TimelineRecorder {
 public:
  TimelineRecorder(double interval_s, const map::TsdfMapConfig& map, Device device,
                   Clock::time_point start)
      : interval_s_(interval_s), map_(map), device_(device), start_(start) {}

  // Called after each scan is given: samples when `mission_s` reached the next boundary.
  void after_scan(double mission_s, pipeline::SlamSystem& slam,
                  std::vector<TimelineSample>* timeline) {
    if (!(interval_s_ > 0.0) || mission_s < next_s_) return;
    timeline->push_back(sample(mission_s, slam));
    while (next_s_ <= mission_s) next_s_ += interval_s_;
  }

  TimelineSample sample(double mission_s, pipeline::SlamSystem& slam) {
    TimelineSample s;
    s.mission_s = mission_s;
    s.wall_s = seconds_since(start_);
    host_memory_mb(&s.host_rss_mb, &s.host_peak_rss_mb);
    s.device_used_mb = device_used_mb(device_);
    for (const pipeline::SubmapInfo& submap : slam.submaps())
      s.map_blocks += submap.statistics.blocks;
    s.map_memory_mb = voxel_memory_mb(s.map_blocks, map_);
    std::vector<double> scans = slam.take_scan_durations();
    s.window_scans = static_cast<int64_t>(scans.size());
    s.scan_p50_ms = 1000.0 * nearest_rank_percentile(&scans, 50.0);
    s.scan_p95_ms = 1000.0 * nearest_rank_percentile(&scans, 95.0);
    s.scan_max_ms = 1000.0 * nearest_rank_percentile(&scans, 100.0);
    const pipeline::SlamTimings timings = slam.timings();
    const pipeline::SlamCounters counters = slam.counters();
    s.submaps = timings.registration.calls;
    s.window_submaps = timings.registration.calls - previous_.registration.calls;
    const double submaps = static_cast<double>(s.window_submaps);
    s.registration_ms_per_submap =
        s.window_submaps > 0
            ? 1000.0 * (timings.registration.total_s - previous_.registration.total_s) / submaps
            : kNaN;
    s.solve_ms_per_submap =
        s.window_submaps > 0
            ? 1000.0 * (timings.backend.total_s - previous_.backend.total_s) / submaps
            : kNaN;
    s.window_optimizations = counters.optimizations - previous_counters_.optimizations;
    s.partners_per_submap = per_submap(
        counters.registration.attempted - previous_counters_.registration.attempted, submaps);
    s.restores_per_submap =
        per_submap(counters.memory.restores - previous_counters_.memory.restores, submaps);
    s.memory = counters.memory;
    previous_ = timings;
    previous_counters_ = counters;
    return s;
  }

 private:
  double interval_s_;
  map::TsdfMapConfig map_;
  Device device_;
  Clock::time_point start_;
  double next_s_ = interval_s_;  // nothing to measure at mission time 0
  pipeline::SlamTimings previous_;
  pipeline::SlamCounters previous_counters_;

  static double per_submap(int64_t count, double submaps) {
    return submaps > 0.0 ? static_cast<double>(count) / submaps : kNaN;
  }
};

void save_map(pipeline::SlamSystem& slam, const map::TsdfMapConfig& map, const std::string& path,
              SlamRunResult* result) {
  const auto start = Clock::now();
  // Streamed submap by submap in their compact forms, as the node's save_map: the map is never
  // held whole, in full or compact form.
  io::MapFileWriter writer(path, map.voxel_size_m, map.voxels_per_side,
                           slam.map_distance_scale_m());
  slam.write_submaps(
      [&](int64_t id, const Eigen::Isometry3d& T_world_submap,
          const std::vector<uint8_t>& encoded) { writer.add_submap(id, T_world_submap, encoded); });
  writer.commit();
  result->map_save_s = seconds_since(start);
  std::ifstream file(path, std::ios::binary | std::ios::ate);
  result->map_file_mb = file ? double(file.tellg()) / (1024.0 * 1024.0) : kNaN;
}

std::string nothing_mapped(const SlamRunResult& result) {
  return "nothing was mapped: " + std::to_string(result.scans_given) +
         " scans were given to the SLAM system and none was integrated (" +
         std::to_string(result.counters.scans_dropped_total()) + " dropped by it, " +
         std::to_string(result.scans_dropped_by_source) +
         " dropped by the input reader); no output was written";
}

// A run that mapped nothing has no result: it fails here, which keeps earlier outputs (the map
// file, the caller's files) instead of replacing them with empty ones. Otherwise saves the map
// when `path` is set.
void save_map_of_run(pipeline::SlamSystem& slam, const map::TsdfMapConfig& map,
                     const std::string& path, SlamRunResult* result) {
  if (result->counters.scans_integrated == 0) throw Error(nothing_mapped(*result));
  if (!path.empty()) save_map(slam, map, path, result);
}

}  // namespace

double nearest_rank_percentile(std::vector<double>* values, double percent) {
  if (values->empty()) return kNaN;
  const double n = static_cast<double>(values->size());
  const size_t rank = static_cast<size_t>(std::max(1.0, std::ceil(percent / 100.0 * n)));
  const size_t index = std::min(values->size(), rank) - 1;
  std::nth_element(values->begin(), values->begin() + static_cast<std::ptrdiff_t>(index),
                   values->end());
  return (*values)[index];
}

void host_memory_mb(double* rss_mb, double* peak_rss_mb) {
  *rss_mb = *peak_rss_mb = kNaN;
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    std::istringstream fields(line);
    std::string key;
    double kib = 0.0;
    if (!(fields >> key >> kib)) continue;
    if (key == "VmRSS:") *rss_mb = kib / 1024.0;
    if (key == "VmHWM:") *peak_rss_mb = kib / 1024.0;
  }
}

SlamRunResult run_slam_system(ScanSource& source, const pipeline::SlamConfig& config,
                              const SlamRunOptions& options) {
  SlamRunResult result;
  const size_t total =
      options.max_scans > 0 ? std::min(options.max_scans, source.size()) : source.size();
  // Offline input waits for room in the queues: nothing is dropped, and the result does not
  // depend on the machine's speed or load.
  pipeline::SlamConfig offline = config;
  offline.wait_when_queues_full = true;
  pipeline::SlamSystem slam(offline);
  const auto start = Clock::now();
  TimelineRecorder timeline(options.timeline_interval_s, config.map, config.device, start);
  SourceScan scan;
  double first_stamp_s = 0.0, last_stamp_s = 0.0;
  while (result.scans_given < total) {
    const auto read_start = Clock::now();
    const bool more = source.next(&scan);
    result.read_s += seconds_since(read_start);
    if (!more) break;
    if (result.scans_given == 0) first_stamp_s = scan.stamp_s;
    last_stamp_s = scan.stamp_s;
    result.odometry.poses.push_back(stamped_pose(scan.stamp_s, scan.T_odom_sensor));
    pipeline::Scan input;
    input.stamp_s = scan.stamp_s;
    input.T_odom_sensor = scan.T_odom_sensor;
    input.points_sensor_m = std::move(scan.points_sensor_m);
    input.colors = std::move(scan.colors);
    input.point_times_s = std::move(scan.point_times_s);
    input.sweep = scan.sweep;
    // add_scan waits while the sensor queue is full (back-pressure instead of drops).
    const auto throttle_start = Clock::now();
    slam.add_scan(std::move(input));
    result.throttle_s += seconds_since(throttle_start);
    ++result.scans_given;
    timeline.after_scan(last_stamp_s - first_stamp_s, slam, &result.timeline);
    if (options.progress_bar && (result.scans_given % 10 == 0 || result.scans_given == total)) {
      draw_progress(result.scans_given, total, seconds_since(start), slam);
    }
  }
  const auto finish_start = Clock::now();
  slam.finish();
  result.finish_s = seconds_since(finish_start);
  result.wall_s = seconds_since(start);
  if (options.timeline_interval_s > 0.0 && result.scans_given > 0)
    result.timeline.push_back(timeline.sample(last_stamp_s - first_stamp_s, slam));
  if (!result.timeline.empty()) result.timeline.back().end = true;
  if (options.progress_bar) std::fprintf(stderr, "\n");

  result.scans_dropped_by_source = source.dropped();
  // The input's time span plus one scan period (what a sensor at that rate takes to deliver it).
  result.input_duration_s = source.duration_s();
  if (options.max_scans > 0 || result.input_duration_s <= 0.0) {
    const size_t n = result.scans_given;
    result.input_duration_s = n > 1 ? (last_stamp_s - first_stamp_s) * n / (n - 1) : 0.0;
  }
  for (const pipeline::StampedPose& pose : slam.corrected_trajectory()) {
    result.corrected.poses.push_back(stamped_pose(pose.stamp_s, pose.T_world_sensor));
  }
  result.mesh = slam.combined_mesh();
  result.counters = slam.counters();
  result.timings = slam.timings();
  result.submaps = slam.submaps();
  result.constraints = slam.constraints();
  for (const pipeline::SubmapInfo& submap : result.submaps)
    result.map_blocks += submap.statistics.blocks;
  result.map_memory_mb = voxel_memory_mb(result.map_blocks, config.map);
  save_map_of_run(slam, config.map, options.map_path, &result);
  return result;
}

SlamRunEvaluation evaluate_slam_run(const ScanSource& source, const SlamRunResult& result,
                                    eval::AlignmentMode alignment, double max_time_gap_s) {
  SlamRunEvaluation evaluation;
  if (source.reference_kind() == ReferenceKind::kNone || source.reference().size() < 3) {
    evaluation.problem = "the input has no reference trajectory";
    return evaluation;
  }
  eval::TrajectoryEvaluationOptions options;
  options.alignment = alignment;
  options.association.max_time_gap_s = max_time_gap_s;
  try {
    evaluation.odometry = eval::evaluate_trajectory(source.reference(), result.odometry, options);
    evaluation.corrected = eval::evaluate_trajectory(source.reference(), result.corrected, options);
    evaluation.available = true;
  } catch (const Error& error) {
    evaluation.problem = error.what();
  }
  return evaluation;
}

TrajectoryShift trajectory_shift(const SlamRunResult& result) {
  // Both trajectories hold the integrated scans' stamps: pair them by stamp.
  TrajectoryShift shift;
  const std::vector<io::StampedPose>& a = result.corrected.poses;
  const std::vector<io::StampedPose>& b = result.odometry.poses;
  double sum_sq = 0.0;
  size_t count = 0, k = 0;
  for (const io::StampedPose& pose : a) {
    while (k < b.size() && b[k].timestamp_s < pose.timestamp_s) ++k;
    if (k == b.size()) break;
    if (b[k].timestamp_s != pose.timestamp_s) continue;
    const double d = (pose.position_m - b[k].position_m).norm();
    sum_sq += d * d;
    shift.max_m = std::max(shift.max_m, d);
    ++count;
  }
  shift.rms_m = count > 0 ? std::sqrt(sum_sq / static_cast<double>(count)) : 0.0;
  return shift;
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
               "%lld too few points, %lld misfit, %lld disagreeing with the odometry; %lld "
               "revisits started from the walls; %lld set aside by the consistency gate at the "
               "end\n",
               static_cast<long long>(c.registration.attempted),
               static_cast<long long>(c.registration.accepted),
               static_cast<long long>(c.registration.rejected_failed),
               static_cast<long long>(c.registration.rejected_too_far),
               static_cast<long long>(c.registration.rejected_too_few_points),
               static_cast<long long>(c.registration.rejected_misfit),
               static_cast<long long>(c.registration.rejected_by_odometry),
               static_cast<long long>(c.registration.started_from_walls),
               static_cast<long long>(c.registrations_set_aside));
  const pipeline::PlaceRecognitionCounts& p = c.place_recognition;
  std::fprintf(out,
               "place recognition: %lld submaps searched, %lld candidates, %lld verified, %lld "
               "accepted, rejected: %lld descriptor, %lld overlap, %lld by the registration (%lld "
               "failed, %lld too far, %lld too few points, %lld misfit, %lld disagreeing with the "
               "odometry), %lld unconfirmed; %lld already linked\n",
               static_cast<long long>(p.queries), static_cast<long long>(p.candidates),
               static_cast<long long>(p.verified), static_cast<long long>(p.accepted),
               static_cast<long long>(p.rejected_descriptor),
               static_cast<long long>(p.rejected_overlap),
               static_cast<long long>(p.verified - p.registration.accepted),
               static_cast<long long>(p.registration.rejected_failed),
               static_cast<long long>(p.registration.rejected_too_far),
               static_cast<long long>(p.registration.rejected_too_few_points),
               static_cast<long long>(p.registration.rejected_misfit),
               static_cast<long long>(p.registration.rejected_by_odometry),
               static_cast<long long>(p.unconfirmed), static_cast<long long>(p.skipped_linked));
  const TrajectoryShift shift = trajectory_shift(result);
  std::fprintf(out,
               "correction: the trajectory moved %.3f m RMS (max %.3f m) from its odometry; "
               "submaps %.3f m RMS (max %.3f m)\n",
               shift.rms_m, shift.max_m, c.correction_rms_m, c.correction_max_m);
  if (c.odometry_drift_estimate_m_per_m > 0.0) {
    std::fprintf(out, "odometry drift estimated from the data: %.4f m/m, %.3f deg/m",
                 c.odometry_drift_estimate_m_per_m, c.odometry_drift_estimate_deg_per_m);
    if (c.revisits_measuring_drift > 0) {
      std::fprintf(out, " (at least what %lld revisits show: %.4f m/m, %.3f deg/m)",
                   static_cast<long long>(c.revisits_measuring_drift), c.revisit_drift_m_per_m,
                   c.revisit_drift_deg_per_m);
    }
    std::fprintf(out, "\n");
  }
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
  std::fprintf(out,
               "de-skewing: %lld scans de-skewed by their point times, %lld with times but no "
               "odometry across the sweep, %lld without times while moving, %lld dropped for bad "
               "times\n",
               static_cast<long long>(c.scans_deskewed),
               static_cast<long long>(c.scans_not_deskewed_no_sweep_odometry),
               static_cast<long long>(c.scans_not_deskewed_no_times_moving),
               static_cast<long long>(c.scans_dropped_bad_point_times));
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

void print_timeline(const std::vector<TimelineSample>& timeline, FILE* out) {
  if (timeline.empty()) return;
  std::fprintf(out, "\n%9s %8s %9s %9s %8s %8s %7s %8s %8s %8s %9s %9s %8s %8s\n", "mission s",
               "wall s", "RSS MB", "peak MB", "blocks", "map MB", "submaps", "scan p50", "scan p95",
               "scan max", "reg ms/sm", "opt ms/sm", "pairs/sm", "rest/sm");
  for (const TimelineSample& s : timeline) {
    std::fprintf(out,
                 "%9.0f %8.1f %9.0f %9.0f %8zu %8.0f %7lld %8.1f %8.1f %8.1f %9.1f %9.1f %8.1f "
                 "%8.1f\n",
                 s.mission_s, s.wall_s, s.host_rss_mb, s.host_peak_rss_mb, s.map_blocks,
                 s.map_memory_mb, static_cast<long long>(s.submaps), s.scan_p50_ms, s.scan_p95_ms,
                 s.scan_max_ms, s.registration_ms_per_submap, s.solve_ms_per_submap,
                 s.partners_per_submap, s.restores_per_submap);
  }
}

}  // namespace tools
}  // namespace covox

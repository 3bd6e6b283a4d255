// map_flight: maps a flight bag (simulate_flight's flight.bag, or any bag run_slam reads) the way
// the SLAM front end does, without any drift correction: every scan is fused into one map
// (pipeline::Mapper, configured from a preset of config/) at its odometry pose (or its true pose
// from a TUM file, for the reference map), the ESDF and the mesh follow incrementally. Prints
// per-module timings, the map size and the odometry's ATE against the bag's reference, and writes
// the mesh. run_slam is the same with submaps and drift correction.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/pipeline/mapper.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "eval/trajectory_evaluation.h"
#include "runner/bag_scan_source.h"

namespace {

using namespace covox;
using Clock = std::chrono::steady_clock;

const char kUsage[] =
    "usage: map_flight [--bag FILE] [options]\n"
    "  --bag FILE             flight bag with the ARCHE layout (default sim_flight/flight.bag)\n"
    "  --poses odometry|truth which poses to fuse the scans at (default odometry)\n"
    "  --truth FILE.tum       cloud-frame poses for --poses truth (default truth.tum next to the "
    "bag)\n"
    "  --device auto|cpu|cuda (default auto)\n"
    "  --preset NAME          the map's configuration: a file in config/ (COVOX_CONFIG_DIR)\n"
    "                         (default arche, what run_slam maps bags with)\n"
    "  --config FILE.yaml     a configuration file applied over the preset\n"
    "  --voxel-size-m S       overrides map.voxel_size_m\n"
    "  --truncation-m T       overrides tsdf.truncation_distance_m\n"
    "  --max-ray-m R          overrides tsdf.max_ray_length_m (points farther only clear space)\n"
    "  --esdf-every N         ESDF update every N scans (default 10: 1 Hz at 10 Hz scans)\n"
    "  --mesh-every N         mesh update every N scans (default 10)\n"
    "  --max-scans N          stop after N scans (0: all)\n"
    "  --mesh FILE.ply        where to write the mesh (default map_flight_mesh.ply)\n";

// Wall time per module, with the stream drained so that CUDA work is charged to its module.
struct ModuleTimer {
  std::string name;
  int64_t calls = 0;
  double seconds = 0.0;
};

template <class Work>
void timed(ModuleTimer* timer, const Stream& stream, Work&& work) {
  const auto start = Clock::now();
  work();
  stream.synchronize();
  timer->seconds += std::chrono::duration<double>(Clock::now() - start).count();
  ++timer->calls;
}

void draw_progress(size_t done, size_t total, double elapsed_s) {
  const int width = 40;
  const double fraction = total > 0 ? static_cast<double>(done) / total : 1.0;
  const int filled = static_cast<int>(fraction * width);
  const double eta_s = done > 0 ? elapsed_s * (total - done) / done : 0.0;
  std::fprintf(stderr, "\r[%s%s] %3.0f%% scan %zu/%zu, %.0f s, ETA %.0f s ",
               std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(),
               100.0 * fraction, done, total, elapsed_s, eta_s);
}

struct Options {
  std::string flight_path;
  std::string pose_source;
  std::string truth_path;
  std::string device_text;
  std::string preset;
  std::string config_path;
  // Overrides of the preset; NaN: not given.
  double voxel_size_m = std::numeric_limits<double>::quiet_NaN();
  double truncation_m = std::numeric_limits<double>::quiet_NaN();
  double max_ray_m = std::numeric_limits<double>::quiet_NaN();
  int64_t esdf_every = 10;
  int64_t mesh_every = 10;
  int64_t max_scans = 0;
  std::string mesh_path;
};

Options parse_options(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  Options o;
  o.flight_path = args.text("--bag", "sim_flight/flight.bag");
  o.pose_source = args.text("--poses", "odometry");
  const size_t slash = o.flight_path.find_last_of('/');
  o.truth_path = args.text(
      "--truth", (slash == std::string::npos ? std::string() : o.flight_path.substr(0, slash + 1)) +
                     "truth.tum");
  o.device_text = args.text("--device", "auto");
  o.preset = args.text("--preset", "arche");
  o.config_path = args.text("--config", "");
  o.voxel_size_m = args.number("--voxel-size-m", o.voxel_size_m, 0.005, 10.0);
  o.truncation_m = args.number("--truncation-m", o.truncation_m, 0.005, 100.0);
  o.max_ray_m = args.number("--max-ray-m", o.max_ray_m, 0.1, 1000.0);
  o.esdf_every = args.integer("--esdf-every", 10, 1, 1000000);
  o.mesh_every = args.integer("--mesh-every", 10, 1, 1000000);
  o.max_scans = args.integer("--max-scans", 0, 0, tools::CommandLine::kIntMax);
  o.mesh_path = args.output_file("--mesh", "map_flight_mesh.ply");
  args.finish();
  if (o.pose_source != "odometry" && o.pose_source != "truth")
    args.fail("--poses must be odometry or truth");
  return o;
}

// The preset, the --config file over it, then the command line's overrides.
pipeline::MapperConfig mapper_config(const Options& o, Device device) {
  pipeline::SlamConfig config = pipeline::load_preset(o.preset);
  if (!o.config_path.empty()) pipeline::load_slam_config(o.config_path, &config);
  config.device = device;
  if (!std::isnan(o.voxel_size_m)) config.map.voxel_size_m = static_cast<float>(o.voxel_size_m);
  if (!std::isnan(o.truncation_m))
    config.tsdf.truncation_distance_m = static_cast<float>(o.truncation_m);
  if (!std::isnan(o.max_ray_m)) config.tsdf.max_ray_length_m = static_cast<float>(o.max_ray_m);
  return pipeline::mapper_config(config);
}

// The time each module took.
struct ModuleTimers {
  ModuleTimer read{"read scan"}, tsdf{"tsdf integrate"}, esdf{"esdf update"}, mesh{"mesh update"},
      final_mesh{"final mesh"};
};

// What the mapping loop gathered: the odometry of every scan read, the points seen, the scans
// without a truth pose (skipped under --poses truth), the welded final mesh and the wall time.
struct FlightRun {
  io::Trajectory odometry;
  int64_t points = 0;
  int64_t scans_without_truth = 0;
  map::Mesh mesh;
  double wall_s = 0.0;
};

// The scan's data moved into the pipeline's scan (points with their times, for de-skewing).
pipeline::Scan to_pipeline_scan(tools::SourceScan* scan) {
  pipeline::Scan input;
  input.stamp_s = scan->stamp_s;
  input.T_odom_sensor = scan->T_odom_sensor;
  input.points_sensor_m = std::move(scan->points_sensor_m);
  input.colors = std::move(scan->colors);
  input.point_times_s = std::move(scan->point_times_s);
  input.sweep = scan->sweep;
  return input;
}

// The pose `scan` is fused at: its odometry pose, or under --poses truth the true pose at its
// stamp (false when the truth does not cover it).
bool fusion_pose(const Options& o, const io::Trajectory& truth_poses, const tools::SourceScan& scan,
                 Eigen::Isometry3d* pose) {
  *pose = scan.T_odom_sensor;
  if (o.pose_source != "truth") return true;
  io::StampedPose stamped;
  if (!eval::interpolate_pose(truth_poses, scan.stamp_s, &stamped)) return false;
  pose->linear() = stamped.orientation.normalized().toRotationMatrix();
  pose->translation() = stamped.position_m;
  return true;
}

// Fuses up to `total` scans, with the ESDF and mesh updates every esdf_every / mesh_every scans,
// then catches up with the scans after the last periodic update and extracts the welded mesh.
FlightRun map_scans(const Options& o, tools::BagScanSource& reader,
                    const io::Trajectory& truth_poses, size_t total, pipeline::Mapper& mapper,
                    ModuleTimers& t) {
  FlightRun run;
  tools::SourceScan scan;
  const auto start = Clock::now();
  for (size_t k = 0; k < total; ++k) {
    bool have = false;
    timed(&t.read, mapper.stream(), [&] { have = reader.next(&scan); });
    if (!have) break;
    io::StampedPose stamped;
    stamped.timestamp_s = scan.stamp_s;
    stamped.position_m = scan.T_odom_sensor.translation();
    stamped.orientation = Eigen::Quaterniond(scan.T_odom_sensor.linear());
    run.odometry.poses.push_back(stamped);
    run.points += static_cast<int64_t>(scan.points_sensor_m.size());
    Eigen::Isometry3d pose;
    if (!fusion_pose(o, truth_poses, scan, &pose)) {
      ++run.scans_without_truth;
      continue;
    }
    timed(&t.tsdf, mapper.stream(), [&] { mapper.integrate(to_pipeline_scan(&scan), pose); });
    if ((k + 1) % o.esdf_every == 0) timed(&t.esdf, mapper.stream(), [&] { mapper.update_esdf(); });
    if ((k + 1) % o.mesh_every == 0) timed(&t.mesh, mapper.stream(), [&] { mapper.update_mesh(); });
    if (k % 10 == 0 || k + 1 == total) {
      draw_progress(k + 1, total, std::chrono::duration<double>(Clock::now() - start).count());
    }
  }
  timed(&t.esdf, mapper.stream(), [&] { mapper.update_esdf(); });
  timed(&t.final_mesh, mapper.stream(), [&] { run.mesh = mapper.extract_mesh(); });
  std::fprintf(stderr, "\n");
  run.wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  return run;
}

void print_timings(const ModuleTimers& m, double wall_s, double flight_s) {
  std::printf("\n%-16s %8s %10s %12s\n", "module", "calls", "total s", "ms/call");
  for (const ModuleTimer* t : {&m.read, &m.tsdf, &m.esdf, &m.mesh, &m.final_mesh}) {
    std::printf("%-16s %8lld %10.2f %12.2f\n", t->name.c_str(), static_cast<long long>(t->calls),
                t->seconds, t->calls ? 1000.0 * t->seconds / t->calls : 0.0);
  }
  std::printf("%-16s %8s %10.2f   (%.2f s per simulated second)\n", "total", "", wall_s,
              flight_s > 0 ? wall_s / flight_s : 0.0);
}

// The odometry's ATE against the bag's reference, without and with a translation + yaw
// alignment.
void print_odometry_ate(const io::Trajectory& reference, const io::Trajectory& estimate) {
  eval::TrajectoryEvaluationOptions options;
  for (eval::AlignmentMode mode :
       {eval::AlignmentMode::kNone, eval::AlignmentMode::kTranslationYaw}) {
    options.alignment = mode;
    const eval::TrajectoryEvaluation evaluation =
        eval::evaluate_trajectory(reference, estimate, options);
    std::printf("odometry ATE RMSE (alignment %s): %.3f m (max %.3f m)\n",
                eval::alignment_mode_name(mode).c_str(), evaluation.absolute_position_m.rmse,
                evaluation.absolute_position_m.max);
  }
}

void print_report(const Options& o, const tools::BagScanSource& reader,
                  const pipeline::Mapper& mapper, const ModuleTimers& timers,
                  const FlightRun& run) {
  const size_t scans = run.odometry.size();
  const double flight_s = reader.duration_s() * scans / std::max<size_t>(1, reader.size());
  const map::TsdfMap& map = mapper.map();
  std::printf("device: %s\npreset: %s%s%s\n", describe_device(mapper.device()).c_str(),
              o.preset.c_str(), o.config_path.empty() ? "" : ", config ", o.config_path.c_str());
  std::printf("flight: %s, %zu scans (%.1f s), %.0f points/scan, fused at %s poses\n",
              o.flight_path.c_str(), scans, flight_s, scans ? double(run.points) / scans : 0.0,
              o.pose_source.c_str());
  if (run.scans_without_truth + reader.dropped() > 0) {
    std::printf("scans skipped: %lld without a truth pose, %lld unreadable or without odometry\n",
                static_cast<long long>(run.scans_without_truth),
                static_cast<long long>(reader.dropped()));
  }
  print_timings(timers, run.wall_s, flight_s);
  const double voxel_bytes =
      sizeof(map::TsdfVoxel) + sizeof(map::ColorVoxel) + sizeof(map::EsdfVoxel);
  std::printf(
      "\nmap: %lld blocks of %d^3 voxels at %.2f m (%.1f MiB of voxels); mesh %zu triangles -> "
      "%s\n",
      static_cast<long long>(map.block_count()), map.voxels_per_side(), map.voxel_size_m(),
      map.block_count() * map.voxels_per_block() * voxel_bytes / (1024.0 * 1024.0),
      run.mesh.triangle_count(), o.mesh_path.c_str());
  if (scans >= 3 && reader.reference().size() >= 3)
    print_odometry_ate(reader.reference(), run.odometry);
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse_options(argc, argv);
  try {
    const Device device = select_device(parse_device_request(o.device_text));
    tools::BagScanSource reader(o.flight_path, tools::BagScanOptions());
    const size_t total =
        o.max_scans > 0 ? std::min<size_t>(o.max_scans, reader.size()) : reader.size();
    io::Trajectory truth_poses;
    if (o.pose_source == "truth") truth_poses = io::read_tum_trajectory(o.truth_path);
    pipeline::Mapper mapper(mapper_config(o, device));
    ModuleTimers timers;
    const FlightRun run = map_scans(o, reader, truth_poses, total, mapper, timers);
    io::write_mesh_ply(o.mesh_path, run.mesh);
    print_report(o, reader, mapper, timers, run);
  } catch (const Error& error) {
    std::cerr << "\nmap_flight: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

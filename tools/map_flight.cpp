// map_flight: maps a flight bag (simulate_flight's flight.bag, or any bag run_slam reads) the way
// the SLAM front end does, without any drift correction: every scan is fused into one TSDF at its
// odometry pose (or its true pose from a TUM file, for the reference map), the ESDF and the mesh
// follow incrementally. Prints per-module timings, the map size and the odometry's ATE against the
// bag's reference, and writes the mesh. run_slam is the same with submaps and drift correction.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "command_line.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/map/tsdf_map.h"
#include "bag_scan_source.h"
#include "covoxslam/io/trajectory_io.h"
#include "trajectory_evaluation.h"

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
    "  --voxel-size-m S       (default 0.2, voxgraph's ARCHE setting)\n"
    "  --truncation-m T       (default 0.6)\n"
    "  --max-ray-m R          points farther only clear space (default 16)\n"
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

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  const std::string flight_path = args.text("--bag", "sim_flight/flight.bag");
  const std::string pose_source = args.text("--poses", "odometry");
  const size_t slash = flight_path.find_last_of('/');
  const std::string truth_path = args.text(
      "--truth", (slash == std::string::npos ? std::string() : flight_path.substr(0, slash + 1)) +
                     "truth.tum");
  const std::string device_text = args.text("--device", "auto");
  const double voxel_size_m = args.number("--voxel-size-m", 0.2);
  const double truncation_m = args.number("--truncation-m", 0.6);
  const double max_ray_m = args.number("--max-ray-m", 16.0);
  const int64_t esdf_every = args.integer("--esdf-every", 10);
  const int64_t mesh_every = args.integer("--mesh-every", 10);
  const int64_t max_scans = args.integer("--max-scans", 0);
  const std::string mesh_path = args.text("--mesh", "map_flight_mesh.ply");
  args.finish();
  if (pose_source != "odometry" && pose_source != "truth")
    args.fail("--poses must be odometry or truth");
  if (esdf_every <= 0 || mesh_every <= 0)
    args.fail("--esdf-every and --mesh-every must be positive");

  try {
    const Device device = select_device(parse_device_request(device_text));
    tools::BagScanSource reader(flight_path, tools::BagScanOptions());
    const size_t total = max_scans > 0 ? std::min<size_t>(max_scans, reader.size()) : reader.size();
    io::Trajectory truth_poses;
    if (pose_source == "truth") truth_poses = io::read_tum_trajectory(truth_path);
    TsdfMapConfig map_config;
    map_config.voxel_size_m = static_cast<float>(voxel_size_m);
    map_config.voxels_per_side = 16;
    TsdfMap map(device, map_config);
    // voxgraph's ARCHE configuration: constant weight with drop-off, sparsity compensation.
    TsdfIntegratorConfig tsdf_config;
    tsdf_config.truncation_distance_m = static_cast<float>(truncation_m);
    tsdf_config.max_ray_length_m = static_cast<float>(max_ray_m);
    tsdf_config.use_const_weight = true;
    tsdf_config.use_weight_dropoff = true;
    tsdf_config.use_sparsity_compensation_factor = true;
    tsdf_config.sparsity_compensation_factor = 20.0f;
    TsdfIntegrator tsdf(tsdf_config);
    EsdfIntegrator esdf(EsdfIntegratorConfig{});
    MeshIntegrator mesher;
    const Stream stream(device);

    ModuleTimer read_timer{"read scan"}, tsdf_timer{"tsdf integrate"}, esdf_timer{"esdf update"},
        mesh_timer{"mesh update"}, final_timer{"final mesh"};
    io::Trajectory odometry;
    int64_t points = 0;
    int64_t scans_without_truth = 0;
    tools::SourceScan scan;
    const auto start = Clock::now();
    for (size_t k = 0; k < total; ++k) {
      bool have = false;
      timed(&read_timer, stream, [&] { have = reader.next(&scan); });
      if (!have) break;
      io::StampedPose stamped;
      stamped.timestamp_s = scan.stamp_s;
      stamped.position_m = scan.T_odom_sensor.translation();
      stamped.orientation = Eigen::Quaterniond(scan.T_odom_sensor.linear());
      odometry.poses.push_back(stamped);
      points += static_cast<int64_t>(scan.points_sensor_m.size());
      Eigen::Isometry3d pose = scan.T_odom_sensor;
      if (pose_source == "truth") {
        if (!tools::interpolate_pose(truth_poses, scan.stamp_s, &stamped)) {
          ++scans_without_truth;
          continue;
        }
        pose.linear() = stamped.orientation.normalized().toRotationMatrix();
        pose.translation() = stamped.position_m;
      }
      timed(&tsdf_timer, stream, [&] { tsdf.integrate(map, scan.points_sensor_m, {}, pose); });
      if ((k + 1) % esdf_every == 0) timed(&esdf_timer, stream, [&] { esdf.update(map, stream); });
      if ((k + 1) % mesh_every == 0)
        timed(&mesh_timer, stream, [&] { mesher.update(map, stream); });
      if (k % 10 == 0 || k + 1 == total) {
        draw_progress(k + 1, total, std::chrono::duration<double>(Clock::now() - start).count());
      }
    }
    // Catch up with the scans after the last periodic update, then the welded final mesh.
    timed(&esdf_timer, stream, [&] { esdf.update(map, stream); });
    Mesh mesh;
    timed(&final_timer, stream, [&] { mesh = mesher.extract_all(map, stream); });
    std::fprintf(stderr, "\n");
    const double wall_s = std::chrono::duration<double>(Clock::now() - start).count();
    io::write_mesh_ply(mesh_path, mesh);

    const size_t scans = odometry.size();
    const double flight_s = reader.duration_s() * scans / std::max<size_t>(1, reader.size());
    std::printf("device: %s\n", describe_device(device).c_str());
    std::printf("flight: %s, %zu scans (%.1f s), %.0f points/scan, fused at %s poses\n",
                flight_path.c_str(), scans, flight_s, scans ? double(points) / scans : 0.0,
                pose_source.c_str());
    if (scans_without_truth + reader.dropped() > 0) {
      std::printf("scans skipped: %lld without a truth pose, %lld unreadable or without odometry\n",
                  static_cast<long long>(scans_without_truth),
                  static_cast<long long>(reader.dropped()));
    }
    std::printf("\n%-16s %8s %10s %12s\n", "module", "calls", "total s", "ms/call");
    for (const ModuleTimer* t :
         {&read_timer, &tsdf_timer, &esdf_timer, &mesh_timer, &final_timer}) {
      std::printf("%-16s %8lld %10.2f %12.2f\n", t->name.c_str(), static_cast<long long>(t->calls),
                  t->seconds, t->calls ? 1000.0 * t->seconds / t->calls : 0.0);
    }
    std::printf("%-16s %8s %10.2f   (%.2f s per simulated second)\n", "total", "", wall_s,
                flight_s > 0 ? wall_s / flight_s : 0.0);
    const double voxel_bytes = sizeof(TsdfVoxel) + sizeof(ColorVoxel) + sizeof(EsdfVoxel);
    std::printf(
        "\nmap: %lld blocks of %d^3 voxels at %.2f m (%.1f MiB of voxels); mesh %zu triangles -> "
        "%s\n",
        static_cast<long long>(map.block_count()), map.voxels_per_side(), voxel_size_m,
        map.block_count() * map.voxels_per_block() * voxel_bytes / (1024.0 * 1024.0),
        mesh.triangle_count(), mesh_path.c_str());
    if (scans >= 3 && reader.reference().size() >= 3) {
      tools::TrajectoryEvaluationOptions options;
      const io::Trajectory& reference = reader.reference();
      const io::Trajectory& estimate = odometry;
      for (tools::AlignmentMode mode :
           {tools::AlignmentMode::kNone, tools::AlignmentMode::kTranslationYaw}) {
        options.alignment = mode;
        const tools::TrajectoryEvaluation evaluation =
            tools::evaluate_trajectory(reference, estimate, options);
        std::printf("odometry ATE RMSE (alignment %s): %.3f m (max %.3f m)\n",
                    tools::alignment_mode_name(mode).c_str(), evaluation.absolute_position_m.rmse,
                    evaluation.absolute_position_m.max);
      }
    }
  } catch (const Error& error) {
    std::cerr << "\nmap_flight: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

// run_slam: the offline runner. Feeds a simulated flight (simulate_flight's flight.covoxsim) through
// the same SlamSystem a robot runs - sensor queue, frontend thread building submaps, submap queue,
// backend thread finishing them and optimising the pose graph - as fast as the machine allows,
// without ROS. Writes the corrected trajectory (TUM), the combined mesh (PLY), optionally the map,
// and prints a per-module timing table and the trajectory error against the truth.
//
// A recorded flight should be processed completely, so unlike a live sensor the runner waits
// when a queue is full instead of letting it drop scans (drops are still counted and printed).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include "command_line.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/map_file.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/pipeline/slam_system.h"
#include "sim_flight_file.h"
#include "trajectory_evaluation.h"

namespace {

using namespace covox;
using Clock = std::chrono::steady_clock;

const char kUsage[] =
    "usage: run_slam [--flight FILE] [options]\n"
    "  --flight FILE               simulated flight (default sim_flight/flight.covoxsim)\n"
    "  --device auto|cpu|cuda      (default auto)\n"
    "  --max-scans N               stop after N scans (0: all)\n"
    "  --voxel-size-m S            (default 0.2, voxgraph's ARCHE setting)\n"
    "  --truncation-m T            (default 0.6)\n"
    "  --max-ray-m R               points farther only clear space (default 16)\n"
    "  --submap-policy time|distance|blocks  (default time, voxgraph's)\n"
    "  --submap-interval-s S       time policy: seconds per submap (default 10)\n"
    "  --submap-distance-m D       distance policy: metres of path per submap (default 20)\n"
    "  --submap-max-blocks N       blocks policy: blocks per submap (default 1000)\n"
    "  --sensor-queue N            sensor queue size in scans (default 20)\n"
    "  --submap-queue N            submap queue size in submaps (default 4)\n"
    "  --trajectory FILE.tum       corrected trajectory (default run_slam_trajectory.tum)\n"
    "  --mesh FILE.ply             combined mesh (default run_slam_mesh.ply)\n"
    "  --map FILE                  also save the map (default: not saved)\n";

void draw_progress(size_t done, size_t total, double elapsed_s, const pipeline::SlamSystem& slam) {
  const int width = 40;
  const double fraction = total > 0 ? static_cast<double>(done) / total : 1.0;
  const int filled = static_cast<int>(fraction * width);
  const double eta_s = done > 0 ? elapsed_s * (total - done) / done : 0.0;
  std::fprintf(stderr, "\r[%s%s] %3.0f%% scan %zu/%zu, %.0f s, ETA %.0f s, queues %zu/%zu ",
               std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(), 100.0 * fraction, done,
               total, elapsed_s, eta_s, slam.sensor_queue_length(), slam.submap_queue_length());
}

void print_timing(const char* name, const pipeline::ModuleTiming& timing) {
  std::printf("%-20s %8lld %10.2f %10.2f %10.2f\n", name, static_cast<long long>(timing.calls), timing.total_s,
              timing.mean_ms(), 1000.0 * timing.max_s);
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  const std::string flight_path = args.text("--flight", "sim_flight/flight.covoxsim");
  const std::string device_text = args.text("--device", "auto");
  const int64_t max_scans = args.integer("--max-scans", 0);
  const double voxel_size_m = args.number("--voxel-size-m", 0.2);
  const double truncation_m = args.number("--truncation-m", 0.6);
  const double max_ray_m = args.number("--max-ray-m", 16.0);
  const std::string policy_text = args.text("--submap-policy", "time");
  const double interval_s = args.number("--submap-interval-s", 10.0);
  const double distance_m = args.number("--submap-distance-m", 20.0);
  const int64_t max_blocks = args.integer("--submap-max-blocks", 1000);
  const int64_t sensor_queue = args.integer("--sensor-queue", 20);
  const int64_t submap_queue = args.integer("--submap-queue", 4);
  const std::string trajectory_path = args.text("--trajectory", "run_slam_trajectory.tum");
  const std::string mesh_path = args.text("--mesh", "run_slam_mesh.ply");
  const std::string map_path = args.text("--map", "");
  args.finish();
  if (max_scans < 0) args.fail("--max-scans must be >= 0");
  if (sensor_queue < 1 || submap_queue < 1) args.fail("--sensor-queue and --submap-queue must be at least 1");

  try {
    pipeline::SlamConfig config;
    config.device = select_device(parse_device_request(device_text));
    config.map.voxel_size_m = static_cast<float>(voxel_size_m);
    config.map.voxels_per_side = 16;
    // voxgraph's ARCHE configuration (as map_flight): constant weight with drop-off and
    // sparsity compensation, so sparse LiDAR surface hits survive the free-space updates.
    config.tsdf.truncation_distance_m = static_cast<float>(truncation_m);
    config.tsdf.max_ray_length_m = static_cast<float>(max_ray_m);
    config.tsdf.use_const_weight = true;
    config.tsdf.use_weight_dropoff = true;
    config.tsdf.use_sparsity_compensation_factor = true;
    config.tsdf.sparsity_compensation_factor = 20.0f;
    config.submaps.policy = pipeline::parse_submap_creation_policy(policy_text);
    config.submaps.interval_s = interval_s;
    config.submaps.distance_m = distance_m;
    config.submaps.max_blocks = max_blocks;
    config.sensor_queue_size = static_cast<size_t>(sensor_queue);
    config.submap_queue_size = static_cast<size_t>(submap_queue);

    sim::FlightFileReader reader(flight_path);
    const size_t total = max_scans > 0 ? std::min<size_t>(max_scans, reader.header().scan_count)
                                       : reader.header().scan_count;
    pipeline::SlamSystem slam(config);

    std::vector<sim::StampedIsometry> truth, odometry;
    double read_s = 0.0, throttle_s = 0.0;
    sim::FlightScan scan;
    const auto start = Clock::now();
    for (size_t k = 0; k < total; ++k) {
      auto read_start = Clock::now();
      if (!reader.next(&scan)) break;
      read_s += std::chrono::duration<double>(Clock::now() - read_start).count();
      truth.push_back({scan.stamp_s, scan.truth});
      odometry.push_back({scan.stamp_s, scan.odometry});
      // Back-pressure instead of drops: wait while the next push would overflow a queue.
      const auto throttle_start = Clock::now();
      // The submap queue keeps one place free for the submap the frontend may be closing now.
      const size_t submap_limit = std::max<size_t>(1, config.submap_queue_size - 1);
      while (slam.sensor_queue_length() >= config.sensor_queue_size || slam.submap_queue_length() >= submap_limit) {
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
      throttle_s += std::chrono::duration<double>(Clock::now() - throttle_start).count();
      pipeline::Scan input;
      input.stamp_s = scan.stamp_s;
      input.T_odom_sensor = scan.odometry;
      input.points_sensor_m = std::move(scan.points_sensor_m);
      slam.add_scan(std::move(input));
      if (k % 10 == 0 || k + 1 == total) {
        draw_progress(k + 1, total, std::chrono::duration<double>(Clock::now() - start).count(), slam);
      }
    }
    const auto finish_start = Clock::now();
    slam.finish();
    const double finish_s = std::chrono::duration<double>(Clock::now() - finish_start).count();
    const double wall_s = std::chrono::duration<double>(Clock::now() - start).count();
    std::fprintf(stderr, "\n");

    io::Trajectory corrected;
    for (const pipeline::StampedPose& pose : slam.corrected_trajectory()) {
      io::StampedPose stamped;
      stamped.timestamp_s = pose.stamp_s;
      stamped.position_m = pose.T_world_sensor.translation();
      stamped.orientation = Eigen::Quaterniond(pose.T_world_sensor.linear()).normalized();
      corrected.poses.push_back(stamped);
    }
    io::write_tum_trajectory(trajectory_path, corrected);
    const Mesh mesh = slam.combined_mesh();
    io::write_mesh_ply(mesh_path, mesh);
    if (!map_path.empty()) {
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
      io::save_map_file(map_path, contents);
    }

    const size_t scans = truth.size();
    const double flight_s =
        scans > 1 ? truth.back().stamp_s - truth.front().stamp_s + (truth[1].stamp_s - truth[0].stamp_s) : 0.0;
    const pipeline::SlamCounters counters = slam.counters();
    const pipeline::SlamTimings timings = slam.timings();
    const std::vector<pipeline::SubmapInfo> submaps = slam.submaps();
    std::printf("device: %s\n", describe_device(config.device).c_str());
    std::printf("flight: %s, %zu scans (%.1f s simulated)\n", flight_path.c_str(), scans, flight_s);
    std::printf("submaps: policy %s, %lld created, %zu in the pose graph, %lld odometry constraints, %lld "
                "optimisations\n",
                pipeline::to_string(config.submaps.policy), static_cast<long long>(counters.submaps_created),
                submaps.size(), static_cast<long long>(counters.odometry_constraints),
                static_cast<long long>(counters.optimizations));
    std::printf("scans: %lld integrated, %lld dropped (queue full %lld, invalid pose %lld, empty %lld, bad stamp "
                "%lld, failed %lld); submaps dropped %lld\n",
                static_cast<long long>(counters.scans_integrated), static_cast<long long>(counters.scans_dropped_total()),
                static_cast<long long>(counters.scans_dropped_queue_full),
                static_cast<long long>(counters.scans_dropped_invalid_pose),
                static_cast<long long>(counters.scans_dropped_empty_cloud),
                static_cast<long long>(counters.scans_dropped_bad_stamp), static_cast<long long>(counters.scans_failed),
                static_cast<long long>(counters.submaps_dropped_queue_full));

    std::printf("\n%-20s %8s %10s %10s %10s\n", "module", "calls", "total s", "mean ms", "max ms");
    print_timing("tsdf integrate", timings.tsdf);
    print_timing("esdf (submap)", timings.esdf);
    print_timing("mesh (submap)", timings.mesh);
    print_timing("backend optimise", timings.backend);
    print_timing("sensor queue wait", timings.sensor_queue_wait);
    print_timing("submap queue wait", timings.submap_queue_wait);
    std::printf("%-20s %8s %10.2f\n", "read flight", "", read_s);
    std::printf("%-20s %8s %10.2f   (input held back while a queue was full)\n", "throttle", "", throttle_s);
    std::printf("%-20s %8s %10.2f   (flush and final optimisation)\n", "finish", "", finish_s);
    std::printf("%-20s %8s %10.2f   (%.2f x real time)\n", "total wall", "", wall_s,
                wall_s > 0 ? flight_s / wall_s : 0.0);

    std::printf("\nmesh: %zu triangles -> %s\ntrajectory: %zu poses -> %s\n", mesh.triangle_count(), mesh_path.c_str(),
                corrected.size(), trajectory_path.c_str());
    if (!map_path.empty()) std::printf("map: %zu submaps -> %s\n", submaps.size(), map_path.c_str());
    std::printf("NOTE: the pose graph has only odometry constraints so far (registration and loop-closure "
                "constraints are not wired in yet), so the corrected trajectory equals the odometry.\n");
    if (scans >= 3 && corrected.size() >= 3) {
      tools::TrajectoryEvaluationOptions options;
      options.alignment = tools::AlignmentMode::kNone;
      const io::Trajectory reference = sim::to_trajectory(truth);
      const tools::TrajectoryEvaluation raw = tools::evaluate_trajectory(reference, sim::to_trajectory(odometry), options);
      const tools::TrajectoryEvaluation slam_result = tools::evaluate_trajectory(reference, corrected, options);
      std::printf("ATE RMSE vs truth (no alignment): odometry %.3f m, corrected %.3f m (max %.3f m)\n",
                  raw.absolute_position_m.rmse, slam_result.absolute_position_m.rmse,
                  slam_result.absolute_position_m.max);
    }
  } catch (const Error& error) {
    std::cerr << "\nrun_slam: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

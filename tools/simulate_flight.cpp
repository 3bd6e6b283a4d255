// simulate_flight: simulates an ARCHE-like flight (figure 8 through a search-and-rescue site,
// Ouster OS1-64, drifting odometry) and writes, into one folder:
//   flight.bag        ROS bag with the ARCHE topic layout (tools/lib/sim_flight_bag.h): clouds,
//                     tf odom -> imu from the odometry, static LiDAR extrinsics, truth positions
//   world.ply         the ground-truth world mesh
//   truth.tum         ground-truth poses of the cloud frame os1_lidar (TUM)
//   odometry.tum      odometry poses of os1_lidar (TUM)
// Deterministic: the same options and seed give byte-identical files.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include "command_line.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/trajectory_io.h"
#include "sim_flight.h"
#include "sim_flight_bag.h"
#include "sim_lidar.h"
#include "sim_random.h"
#include "sim_site.h"

namespace {

using namespace covox;

const char kUsage[] =
    "usage: simulate_flight [--output-dir DIR] [options]\n"
    "  --output-dir DIR         where the files go (default sim_flight; created if missing)\n"
    "  --seed N                 world, noise and drift seed (default 1)\n"
    "  --columns N              LiDAR horizontal resolution (default 1024, OS1-64; 512 or 256 for "
    "fast CPU runs)\n"
    "  --rows N                 LiDAR beams (default 64)\n"
    "  --range-noise-m S        range noise standard deviation (default 0.02)\n"
    "  --dropout P              probability that a beam returns nothing (default 0.01)\n"
    "  --max-range-m R          LiDAR range limit (default 120)\n"
    "  --path-length-m L        figure-8 length (default 400)\n"
    "  --speed-m-per-s V        flight speed (default 2)\n"
    "  --min-drift-m D          least final odometry drift (default 3)\n"
    "  --drift-scale F          multiplies every drift rate (default 1; 0: odometry equals the "
    "truth,\n"
    "                           which isolates the mapping's own error)\n"
    "  --max-scans N            stop after N scans (0: the whole flight)\n";

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  const std::string output_dir = args.text("--output-dir", "sim_flight");
  const uint64_t seed = static_cast<uint64_t>(args.integer("--seed", 1));
  sim::LidarConfig lidar;
  lidar.columns = static_cast<int>(args.integer("--columns", lidar.columns));
  lidar.rows = static_cast<int>(args.integer("--rows", lidar.rows));
  lidar.range_noise_m = args.number("--range-noise-m", lidar.range_noise_m);
  lidar.dropout_probability = args.number("--dropout", lidar.dropout_probability);
  lidar.max_range_m = args.number("--max-range-m", lidar.max_range_m);
  sim::FlightConfig flight;
  flight.path_length_m = args.number("--path-length-m", flight.path_length_m);
  flight.speed_m_per_s = args.number("--speed-m-per-s", flight.speed_m_per_s);
  sim::DriftConfig drift;
  drift.min_final_drift_m = args.number("--min-drift-m", drift.min_final_drift_m);
  const double drift_scale = args.number("--drift-scale", 1.0);
  if (!(drift_scale >= 0.0)) args.fail("--drift-scale must be a number >= 0");
  const int64_t max_scans = args.integer("--max-scans", 0);
  args.finish();

  try {
    sim::validate(lidar);
    const auto start = std::chrono::steady_clock::now();
    // With its parents (a nested --output-dir used to fail only at the first write); an existing
    // folder is fine.
    std::error_code folder_error;
    std::filesystem::create_directories(output_dir, folder_error);
    if (folder_error)
      throw Error("cannot create the output folder " + output_dir + ": " + folder_error.message());
    const sim::Figure8Path path(flight);
    const sim::Site site = sim::build_site(sim::SiteConfig(), path, seed);
    std::vector<sim::StampedIsometry> truth = sim::simulate_truth(path, flight);
    std::vector<sim::StampedIsometry> odometry =
        sim::simulate_odometry(truth, drift.scaled(drift_scale), seed);
    if (max_scans > 0 && static_cast<size_t>(max_scans) < truth.size()) {
      truth.resize(max_scans);
      odometry.resize(max_scans);
    }
    io::write_mesh_ply(output_dir + "/world.ply", site.world.to_mesh());
    // The trajectories of the cloud frame, which is what run_slam estimates.
    std::vector<sim::StampedIsometry> truth_lidar = truth, odometry_lidar = odometry;
    for (size_t k = 0; k < truth.size(); ++k) {
      truth_lidar[k].pose = truth[k].pose * sim::T_os1_sensor_os1_lidar();
      odometry_lidar[k].pose = odometry[k].pose * sim::T_os1_sensor_os1_lidar();
    }
    io::write_tum_trajectory(output_dir + "/truth.tum", sim::to_trajectory(truth_lidar));
    io::write_tum_trajectory(output_dir + "/odometry.tum", sim::to_trajectory(odometry_lidar));

    sim::FlightBagWriter writer(output_dir + "/flight.bag");
    size_t total_points = 0;
    for (size_t k = 0; k < truth.size(); ++k) {
      const std::vector<Vec3f> points =
          sim::simulate_scan(site.world, lidar, truth[k].pose, sim::stream_seed(seed, 0x5CA7, k));
      total_points += points.size();
      writer.write_scan(truth[k].stamp_s, truth[k].pose, odometry[k].pose, points, {});
      if (k % 20 == 0 || k + 1 == truth.size()) {
        std::fprintf(stderr, "\rsimulating scan %zu / %zu", k + 1, truth.size());
      }
    }
    writer.close();
    std::fprintf(stderr, "\n");
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    double max_drift = 0.0;
    for (size_t k = 0; k < truth.size(); ++k) {
      max_drift = std::max(max_drift,
                           (truth[k].pose.translation() - odometry[k].pose.translation()).norm());
    }
    std::printf("world: %zu primitives, %zu buildings, ground %.0f x %.0f m\n",
                site.world.primitive_count(), site.buildings.size(),
                site.high_m.x() - site.low_m.x(), site.high_m.y() - site.low_m.y());
    std::printf(
        "flight: %.1f m figure 8 (lobes %.1f x %.1f m) at %.1f m/s, %zu scans of %d x %d beams, "
        "%.0f points/scan\n",
        path.length_m(), 2.0 * path.lobe_half_length_m(), path.lobe_width_m(), flight.speed_m_per_s,
        truth.size(), lidar.columns, lidar.rows,
        truth.empty() ? 0.0 : double(total_points) / truth.size());
    std::printf("odometry drift: final %.2f m, max %.2f m\n", sim::final_drift_m(truth, odometry),
                max_drift);
    std::printf(
        "wrote %s/{flight.bag,world.ply,truth.tum,odometry.tum} (%llu bag messages) in %.1f s\n",
        output_dir.c_str(), static_cast<unsigned long long>(writer.message_count()), seconds);
  } catch (const Error& error) {
    std::cerr << "simulate_flight: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

// simulate_flight: simulates an ARCHE-like flight (figure 8 through a search-and-rescue site,
// Ouster OS1-64, drifting odometry) and writes, into one folder:
//   flight.bag        ROS bag with the ARCHE topic layout (sim/sim_flight_bag.h): clouds
//                     (distorted by the motion over each sweep, with per-point times, unless
//                     --instantaneous-scan), tf odom -> imu from the odometry at 100 Hz, static
//                     LiDAR extrinsics, truth positions
//   world.ply         the ground-truth world mesh
//   truth.tum         ground-truth poses of the cloud frame os1_lidar (TUM)
//   odometry.tum      odometry poses of os1_lidar (TUM)
// Deterministic: the same options and seed give byte-identical files.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include "cli/command_line.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/trajectory_io.h"
#include "sim/sim_flight.h"
#include "sim/sim_flight_bag.h"
#include "sim/sim_mission.h"
#include "sim/sim_mission_bag.h"

namespace {

using namespace covox;

const char kUsage[] =
    "usage: simulate_flight [--output-dir DIR] [options]\n"
    "  --output-dir DIR         where the files go (default sim_flight; created if missing)\n"
    "  --max-scans N            stop after N scans (0: the whole flight)\n";

// The trajectories of the cloud frame os1_lidar, which is what run_slam estimates.
void write_trajectories(const std::string& output_dir, const sim::SimulatedMission& mission) {
  std::vector<sim::StampedIsometry> truth_lidar = mission.truth();
  std::vector<sim::StampedIsometry> odometry_lidar = mission.odometry();
  for (size_t k = 0; k < truth_lidar.size(); ++k) {
    truth_lidar[k].pose = truth_lidar[k].pose * sim::T_os1_sensor_os1_lidar();
    odometry_lidar[k].pose = odometry_lidar[k].pose * sim::T_os1_sensor_os1_lidar();
  }
  io::write_tum_trajectory(output_dir + "/truth.tum", sim::to_trajectory(truth_lidar));
  io::write_tum_trajectory(output_dir + "/odometry.tum", sim::to_trajectory(odometry_lidar));
}

// Generates the scans one by one straight into the bag: memory stays flat in the flight's length.
// Returns the number of points written; adds the seconds spent ray casting to `generation_s`.
size_t write_bag(const std::string& path, const sim::SimulatedMission& mission,
                 uint64_t* message_count, double* generation_s) {
  sim::FlightBagWriter writer(path);
  size_t total_points = 0;
  const size_t count = mission.size();
  for (size_t k = 0; k < count; ++k) {
    const auto start = std::chrono::steady_clock::now();
    const sim::SweepScan scan = mission.scan(k);
    *generation_s +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    total_points += scan.points_sensor_m.size();
    sim::write_mission_scan(&writer, mission, k, scan);
    if (k % 20 == 0 || k + 1 == count) {
      std::fprintf(stderr, "\rsimulating scan %zu / %zu", k + 1, count);
    }
  }
  writer.close();
  std::fprintf(stderr, "\n");
  *message_count = writer.message_count();
  return total_points;
}

void print_summary(const sim::SimulatedMission& mission, size_t total_points) {
  const std::vector<sim::StampedIsometry>& truth = mission.truth();
  const std::vector<sim::StampedIsometry>& odometry = mission.odometry();
  double max_drift = 0.0;
  for (size_t k = 0; k < truth.size(); ++k) {
    max_drift =
        std::max(max_drift, (truth[k].pose.translation() - odometry[k].pose.translation()).norm());
  }
  const sim::Site& site = mission.site();
  std::printf("world: %zu primitives, %zu buildings, ground %.0f x %.0f m\n",
              site.world.primitive_count(), site.buildings.size(), site.high_m.x() - site.low_m.x(),
              site.high_m.y() - site.low_m.y());
  std::printf("flight: %s, %.0f points/scan\n", sim::describe_flight(mission).c_str(),
              truth.empty() ? 0.0 : double(total_points) / truth.size());
  const double final_drift = sim::final_drift_m(truth, odometry);
  const double distance_m = mission.distance_flown_m(truth.size());
  std::printf("odometry drift: final %.2f m (%.2f %% of %.1f m flown), max %.2f m\n", final_drift,
              distance_m > 0.0 ? 100.0 * final_drift / distance_m : 0.0, distance_m, max_drift);
  std::printf("motion: peak yaw rate %.1f deg/s; scans %s\n",
              sim::peak_yaw_rate_deg_per_s(mission.path(), mission.options().flight),
              mission.options().lidar.instantaneous
                  ? "cast at once (--instantaneous-scan)"
                  : "distorted by the motion over each sweep, with per-point times");
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, std::string(kUsage) + sim::kSimulationUsage);
  const int64_t max_scans = args.integer("--max-scans", 0, 0, tools::CommandLine::kIntMax);
  const sim::SimulationOptions options = sim::read_simulation_options(args);
  // Last: the folder is created only once every other value was read.
  const std::string output_dir = args.output_folder("--output-dir", "sim_flight");
  args.finish();

  try {
    const auto start = std::chrono::steady_clock::now();
    const sim::SimulatedMission mission(options,
                                        max_scans > 0 ? static_cast<size_t>(max_scans) : 0);
    io::write_mesh_ply(output_dir + "/world.ply", mission.site().world.to_mesh());
    write_trajectories(output_dir, mission);
    uint64_t message_count = 0;
    double generation_s = 0.0;
    const size_t total_points =
        write_bag(output_dir + "/flight.bag", mission, &message_count, &generation_s);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    print_summary(mission, total_points);
    std::printf(
        "wrote %s/{flight.bag,world.ply,truth.tum,odometry.tum} (%llu bag messages) in %.1f s, "
        "%.1f s of it generating scans (%.2f ms per scan)\n",
        output_dir.c_str(), static_cast<unsigned long long>(message_count), seconds, generation_s,
        mission.size() > 0 ? 1000.0 * generation_s / mission.size() : 0.0);
  } catch (const Error& error) {
    std::cerr << "simulate_flight: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

// The offline runner (tools/run_slam, runner/slam_run.*) on a tiny simulated flight: the
// library run integrates every scan with the odometry read back exactly as the simulator wrote
// it; the run_slam program writes the trajectory, the mesh, the map and the timing table; a
// missing bag or a wrong topic ends it with an error that names the problem. Parameter files
// parse like the nodelet's; RGB-D folders become clouds on their pixels with the asked drift.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "runner/bag_scan_source.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/map_file.h"
#include "runner/dataset_scan_sources.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "sim/sim_flight.h"
#include "sim/sim_flight_bag.h"
#include "sim/sim_lidar.h"
#include "sim/sim_random.h"
#include "sim/sim_site.h"
#include "runner/slam_run.h"

namespace covox {
namespace tools {
namespace {

namespace fs = std::filesystem;

constexpr size_t kScans = 20;  // 2 s of flight at 10 Hz
constexpr uint64_t kSeed = 3;

// A short figure 8 (small site, fast to build) and its first kScans scans, 128 x 64 beams.
struct TinyFlight {
  sim::FlightConfig flight;
  std::vector<sim::StampedIsometry> truth, odometry;

  explicit TinyFlight(const std::string& bag_path) {
    flight.lobe_half_length_m = 20.0;
    flight.path_length_m = 120.0;
    const sim::Figure8Path figure8(flight);
    const sim::Site site = sim::build_site(sim::SiteConfig(), figure8, kSeed);
    truth = sim::simulate_truth(figure8, flight);
    odometry = sim::simulate_odometry(truth, sim::DriftConfig(), kSeed);
    sim::LidarConfig lidar;
    lidar.columns = 128;
    sim::FlightBagWriter writer(bag_path);
    for (size_t k = 0; k < kScans; ++k) {
      writer.write_scan(
          truth[k].stamp_s, truth[k].pose, odometry[k].pose,
          sim::simulate_scan(site.world, lidar, truth[k].pose, sim::stream_seed(kSeed, 0x5CA7, k)),
          {});
    }
    writer.close();
  }
};

class OfflineRunner : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    folder_ = new fs::path(fs::temp_directory_path() /
                           ("covoxslam_offline_runner_" + std::to_string(::getpid())));
    fs::create_directories(*folder_);
    flight_ = new TinyFlight((*folder_ / "flight.bag").string());
  }
  static void TearDownTestSuite() {
    fs::remove_all(*folder_);
    delete flight_;
    delete folder_;
  }
  static std::string bag() { return (*folder_ / "flight.bag").string(); }
  static fs::path folder() { return *folder_; }
  static fs::path* folder_;
  static TinyFlight* flight_;
};
fs::path* OfflineRunner::folder_ = nullptr;
TinyFlight* OfflineRunner::flight_ = nullptr;

TEST_F(OfflineRunner, LibraryRunIntegratesEveryScanWithTheBagsOdometry) {
  BagScanSource source(bag(), BagScanOptions());
  pipeline::SlamConfig config = pipeline::load_preset("arche");
  config.submaps.interval_s = 0.5;  // four submaps, so that the backend has a graph to optimise
  SlamRunOptions options;
  options.progress_bar = false;
  const SlamRunResult result = run_slam_system(source, config, options);
  EXPECT_EQ(result.scans_given, kScans);
  EXPECT_EQ(result.counters.scans_integrated, static_cast<int64_t>(kScans));
  EXPECT_EQ(result.counters.scans_dropped_total(), 0);
  EXPECT_GE(result.submaps.size(), 3u);
  EXPECT_GT(result.mesh.triangle_count(), 1000u);
  ASSERT_EQ(result.corrected.size(), kScans);
  ASSERT_EQ(result.odometry.size(), kScans);
  // The runner counts one scan period per scan (the last scan covers its period too).
  EXPECT_NEAR(result.input_duration_s, kScans / flight_->flight.scan_rate_hz, 1e-6);
  for (size_t k = 0; k < kScans; ++k) {
    // The runner's odometry of the cloud frame is the simulator's, through the bag's tf tree.
    const Eigen::Vector3d expected =
        (flight_->odometry[k].pose * sim::T_os1_sensor_os1_lidar()).translation();
    ASSERT_LT((result.odometry.poses[k].position_m - expected).norm(), 1e-6) << "scan " << k;
  }
  const SlamRunEvaluation evaluation =
      evaluate_slam_run(source, result, eval::AlignmentMode::kTranslationYaw, 0.1);
  ASSERT_TRUE(evaluation.available) << evaluation.problem;
  EXPECT_EQ(evaluation.corrected.aligned.size(), kScans);
}

// The timeline's windows partition the run: every integrated scan's time, every submap and its
// registration pairs are in exactly one window, samples come at each interval of mission time,
// and the last sample's map is the run's.
TEST_F(OfflineRunner, TimelineWindowsPartitionTheScansAndSubmaps) {
  BagScanSource source(bag(), BagScanOptions());
  pipeline::SlamConfig config = pipeline::load_preset("arche");
  config.submaps.interval_s = 0.5;
  SlamRunOptions options;
  options.progress_bar = false;
  options.timeline_interval_s = 0.5;
  const SlamRunResult result = run_slam_system(source, config, options);
  // Scans every 0.1 s over 1.9 s: samples near 0.5, 1.0 and 1.5 s, then one after finish().
  ASSERT_EQ(result.timeline.size(), 4u);
  int64_t scans = 0, submaps = 0;
  double pairs = 0.0, restores = 0.0;
  for (size_t k = 0; k < result.timeline.size(); ++k) {
    const TimelineSample& t = result.timeline[k];
    if (t.window_submaps > 0) {
      pairs += t.partners_per_submap * static_cast<double>(t.window_submaps);
      restores += t.restores_per_submap * static_cast<double>(t.window_submaps);
    }
    // The first scan at or past each boundary (stamps are not exact tenths).
    if (k < 3) {
      EXPECT_GE(t.mission_s, 0.5 * (k + 1) - 1e-9) << "sample " << k;
      EXPECT_LT(t.mission_s, 0.5 * (k + 1) + 0.1) << "sample " << k;
    }
    EXPECT_EQ(t.end, k == 3);
    scans += t.window_scans;
    submaps += t.window_submaps;
    EXPECT_EQ(t.submaps, submaps) << "sample " << k;
    if (k > 0) {
      EXPECT_GE(t.wall_s, result.timeline[k - 1].wall_s);
    }
    if (t.window_scans > 0) {
      EXPECT_LE(t.scan_p50_ms, t.scan_p95_ms);
      EXPECT_LE(t.scan_p95_ms, t.scan_max_ms);
    }
    EXPECT_GT(t.host_rss_mb, 0.0);
    EXPECT_GE(t.host_peak_rss_mb, t.host_rss_mb);
  }
  EXPECT_EQ(scans, static_cast<int64_t>(kScans));
  EXPECT_EQ(submaps, static_cast<int64_t>(result.submaps.size()));
  // Per-submap counts times the window's submaps add up to the run's counters.
  EXPECT_NEAR(pairs, static_cast<double>(result.counters.registration.attempted), 1e-6);
  EXPECT_NEAR(restores, static_cast<double>(result.counters.memory.restores), 1e-6);
  EXPECT_GT(result.counters.registration.attempted, 0);
  EXPECT_EQ(result.timeline.back().map_blocks, result.map_blocks);
  EXPECT_DOUBLE_EQ(result.timeline.back().map_memory_mb, result.map_memory_mb);
}

// run_slam next to this test binary (plain CMake and catkin both put programs in one folder).
fs::path run_slam_program() {
  return fs::read_symlink("/proc/self/exe").parent_path() / "run_slam";
}

struct ProgramRun {
  int status = -1;
  std::string output;  // stdout and stderr
};

ProgramRun run_program(const std::string& arguments, const fs::path& log) {
  const std::string command =
      run_slam_program().string() + " " + arguments + " > " + log.string() + " 2>&1";
  ProgramRun run;
  const int raw = std::system(command.c_str());
  run.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  std::ifstream file(log);
  std::stringstream text;
  text << file.rdbuf();
  run.output = text.str();
  return run;
}

std::vector<std::vector<double>> tum_rows(const fs::path& path) {
  std::ifstream file(path);
  std::vector<std::vector<double>> rows;
  for (std::string line; std::getline(file, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::vector<double> row;
    for (double value; fields >> value;) row.push_back(value);
    rows.push_back(row);
  }
  return rows;
}

TEST_F(OfflineRunner, ProgramWritesTrajectoryMeshMapAndTimingTable) {
  if (!fs::exists(run_slam_program())) GTEST_SKIP() << "run_slam is not built next to the tests";
  const fs::path out = folder() / "out";
  fs::create_directories(out);
  const ProgramRun run = run_program(
      "--bag " + bag() + " --device cpu --quiet --submap-interval-s 0.5 --trajectory " +
          (out / "slam.tum").string() + " --odometry-trajectory " +
          (out / "odometry.tum").string() + " --mesh " + (out / "mesh.ply").string() + " --map " +
          (out / "map.covoxmap").string() + " --json " + (out / "pipeline.json").string(),
      out / "log.txt");
  ASSERT_EQ(run.status, 0) << run.output;

  // Trajectories: one TUM row (stamp, x y z, qx qy qz qw) per scan, at the bag's stamps.
  const auto slam = tum_rows(out / "slam.tum");
  const auto odometry = tum_rows(out / "odometry.tum");
  ASSERT_EQ(slam.size(), kScans);
  ASSERT_EQ(odometry.size(), kScans);
  for (size_t k = 0; k < kScans; ++k) {
    ASSERT_EQ(slam[k].size(), 8u);
    EXPECT_NEAR(slam[k][0], flight_->truth[k].stamp_s, 1e-6);
    EXPECT_NEAR(odometry[k][0], flight_->truth[k].stamp_s, 1e-6);
    const double quaternion_norm = std::sqrt(slam[k][4] * slam[k][4] + slam[k][5] * slam[k][5] +
                                             slam[k][6] * slam[k][6] + slam[k][7] * slam[k][7]);
    EXPECT_NEAR(quaternion_norm, 1.0, 1e-6);
  }

  // Mesh: a PLY with vertices and faces.
  std::ifstream mesh(out / "mesh.ply");
  std::string magic, line;
  std::getline(mesh, magic);
  EXPECT_EQ(magic, "ply");
  long vertices = 0, faces = 0;
  while (std::getline(mesh, line) && line != "end_header") {
    std::sscanf(line.c_str(), "element vertex %ld", &vertices);
    std::sscanf(line.c_str(), "element face %ld", &faces);
  }
  EXPECT_GT(vertices, 1000);
  EXPECT_GT(faces, 1000);

  // Map: loads back with the runner's voxel size and its submaps.
  const io::MapFileContents map = io::load_map_file((out / "map.covoxmap").string());
  EXPECT_FLOAT_EQ(map.voxel_size_m, 0.2f);
  EXPECT_GE(map.submaps.size(), 3u);
  size_t blocks = 0;
  for (const io::SubmapRecord& submap : map.submaps) blocks += submap.blocks.size();
  EXPECT_GT(blocks, 0u);

  // Timing table: every module's row, the total and the map line.
  for (const char* row :
       {"module ", "tsdf integrate", "esdf (submap)", "mesh (submap)", "registration",
        "backend optimise", "sensor queue wait", "submap queue wait", "total wall", "map: "}) {
    EXPECT_NE(run.output.find(row), std::string::npos) << "no '" << row << "' in:\n" << run.output;
  }
  EXPECT_NE(run.output.find("covoxslam "), std::string::npos) << "no ATE line in:\n" << run.output;
  std::ifstream json(out / "pipeline.json");
  std::stringstream report;
  report << json.rdbuf();
  EXPECT_NE(report.str().find("real-time factor"), std::string::npos);
}

TEST_F(OfflineRunner, ProgramNamesAMissingBagOrAWrongTopic) {
  if (!fs::exists(run_slam_program())) GTEST_SKIP() << "run_slam is not built next to the tests";
  const fs::path out = folder() / "bad";
  fs::create_directories(out);
  const std::string outputs = " --device cpu --quiet --trajectory " + (out / "t.tum").string() +
                              " --mesh " + (out / "m.ply").string();

  const std::string missing = (folder() / "no_such.bag").string();
  ProgramRun run = run_program("--bag " + missing + outputs, out / "missing.txt");
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_NE(run.output.find(missing), std::string::npos) << "the error does not name the bag:\n"
                                                         << run.output;

  run =
      run_program("--bag " + bag() + " --cloud-topic /no/such/points" + outputs, out / "topic.txt");
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_NE(run.output.find("/no/such/points"), std::string::npos) << run.output;
  // ... and lists the topics the bag does have.
  EXPECT_NE(run.output.find("/penguin/os1_cloud_node/points"), std::string::npos) << run.output;

  // Nothing half-written is left behind.
  EXPECT_FALSE(fs::exists(out / "t.tum"));
  EXPECT_FALSE(fs::exists(out / "m.ply"));
}

// Every output is checked before the input is read: a missing folder ends the run at once with
// the option and the path, instead of after mapping the whole input.
TEST_F(OfflineRunner, ProgramChecksEveryOutputBeforeAnyWork) {
  if (!fs::exists(run_slam_program())) GTEST_SKIP() << "run_slam is not built next to the tests";
  const fs::path out = folder() / "early";
  fs::create_directories(out);
  const std::string missing = "/nonexistent/dir/output.bin";
  for (const char* option : {"--map", "--mesh", "--trajectory", "--odometry-trajectory",
                             "--reference-trajectory", "--graph", "--json", "--timeline-plot"}) {
    const auto start = std::chrono::steady_clock::now();
    const ProgramRun run = run_program("--bag " + bag() + " --device cpu --quiet " + option + " " +
                                           missing + " --trajectory " + (out / "t.tum").string(),
                                       out / "log.txt");
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (std::string(option) == "--trajectory") {
      // Given twice: refused as such, also at once.
      EXPECT_NE(run.output.find("--trajectory is given twice"), std::string::npos) << run.output;
    } else {
      EXPECT_NE(run.output.find(std::string(option) + " " + missing), std::string::npos)
          << run.output;
      EXPECT_NE(run.output.find("No such file or directory"), std::string::npos) << run.output;
    }
    EXPECT_EQ(run.status, 2) << option << ": " << run.output;
    EXPECT_LT(seconds, 1.0) << option;
  }
  EXPECT_FALSE(fs::exists(out / "t.tum"));
  // A folder as the output file, and a folder as --config.
  ProgramRun run = run_program("--bag " + bag() + " --quiet --mesh " + out.string(), out / "l");
  EXPECT_EQ(run.status, 2);
  EXPECT_NE(run.output.find("is a folder"), std::string::npos) << run.output;
  run = run_program("--bag " + bag() + " --quiet --config " + out.string() + " --trajectory " +
                        (out / "t.tum").string(),
                    out / "l");
  EXPECT_EQ(run.status, 2);
  EXPECT_NE(run.output.find("--config"), std::string::npos) << run.output;
}

// A run in which every scan is dropped (here: every point nearer than --min-range-m) fails and
// leaves the outputs of an earlier run as they were.
TEST_F(OfflineRunner, ARunThatMapsNothingFailsAndKeepsEarlierOutputs) {
  if (!fs::exists(run_slam_program())) GTEST_SKIP() << "run_slam is not built next to the tests";
  const fs::path out = folder() / "nothing";
  fs::create_directories(out);
  for (const char* name : {"t.tum", "m.ply", "map.bin"}) std::ofstream(out / name) << "earlier";
  const ProgramRun run =
      run_program("--bag " + bag() + " --device cpu --quiet --min-range-m 999 --trajectory " +
                      (out / "t.tum").string() + " --mesh " + (out / "m.ply").string() + " --map " +
                      (out / "map.bin").string(),
                  out / "log.txt");
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_NE(run.output.find("nothing was mapped"), std::string::npos) << run.output;
  for (const char* name : {"t.tum", "m.ply", "map.bin"}) {
    std::ifstream file(out / name);
    std::string text;
    std::getline(file, text);
    EXPECT_EQ(text, "earlier") << name << " was replaced";
  }
}

TEST(OfflineRunnerInputs, RgbdFolderCloudsProjectOntoTheirPixelsAndOdometryDriftsAsAsked) {
  const std::string folder = io::data_directory() + "/7scenes-redkitchen";
  if (!fs::exists(folder)) GTEST_SKIP() << "shared data not found at '" << folder << "'";
  RgbdScanOptions options;
  options.pixel_stride = 8;
  options.max_frames = 40;
  options.min_final_drift_m = 0.2;
  RgbdScanSource source(folder, options);
  ASSERT_EQ(source.size(), 40u);
  ASSERT_EQ(source.reference().size(), 40u);
  EXPECT_EQ(source.reference_kind(), ReferenceKind::kGroundTruth);
  EXPECT_GE(source.final_drift_m(), 0.2);
  const double fx = 585.0, fy = 585.0, cx = 320.0,
               cy = 240.0;  // the folder's camera-intrinsics.txt
  SourceScan scan;
  ASSERT_TRUE(source.next(&scan));
  // The odometry starts exactly at the reference.
  EXPECT_LT((scan.T_odom_sensor.translation() - source.reference().poses[0].position_m).norm(),
            1e-9);
  ASSERT_GT(scan.points_sensor_m.size(), 1000u);
  EXPECT_EQ(scan.colors.size(), scan.points_sensor_m.size());
  for (const Vec3f& p : scan.points_sensor_m) {
    ASSERT_GT(p.z, 0.0f);
    const double u = fx * p.x / p.z + cx, v = fy * p.y / p.z + cy;
    // Every point is the centre of a pixel on the stride grid.
    ASSERT_NEAR(u / 8.0, std::round(u / 8.0), 1e-3);
    ASSERT_NEAR(v / 8.0, std::round(v / 8.0), 1e-3);
  }
  size_t frames = 1;
  while (source.next(&scan)) ++frames;
  EXPECT_EQ(frames, 40u);
  const double drift_m =
      (scan.T_odom_sensor.translation() - source.reference().poses.back().position_m).norm();
  EXPECT_NEAR(drift_m, source.final_drift_m(), 1e-9);
}

}  // namespace
}  // namespace tools
}  // namespace covox

// benchmark_accuracy: the trajectory accuracy of covoxslam against odometry alone on the inputs
// the project evaluates, one offline SLAM run each (runner/slam_run.h) with the configuration
// run_slam gives that kind of input (tools::default_preset: nothing per case), in one report:
//   sim                simulated 200 s drone flights generated in process (run_slam --simulate
//                      --seed N --columns 256): ATE RMSE against the truth
//   bag                a flight bag (--bag; make demo writes one)
//   7scenes            redkitchen RGB-D, the dataset's poses perturbed by a deterministic drift of
//                      >= 0.3 m as odometry: ATE RMSE against the dataset's poses
//   7scenes-long       redkitchen frames 0-599 (revisits): drift seeds 1-5 and no drift
//   mulran             Riverside02 keyframes, LiDAR-inertial odometry: distance to
//                      optimized_poses.txt, another SLAM system's estimate ("distance to
//                      reference", never accuracy)
//   livox              HKU-2 Livox keyframes, FAST-LIO2 odometry (already good): distance to
//                      optimized_poses.txt (another SLAM system's loop-closed estimate), as
//                      recorded (covoxslam must not end farther than the odometry) and with the
//                      simulator's drift added, seeds 1-5 (covoxslam must bring it back)
//   kitti07            the lidar-scans dump (5 keyframes, graph.txt poses, another SLAM system's
//                      estimate): no drift (covoxslam must leave the given poses alone) and the
//                      simulator's drift of >= 0.3 m (covoxslam must come closer than odometry)
//   loops              long simulated flights generated in process: two laps of a large figure 8
//                      whose odometry ends tens of metres off (--loop-drift-percent), and seed 0:
//                      the same flight without drift. Every loop closure is checked against the
//                      truth; the program exits with 2 when one is wrong.
// `--cases all` is the whole matrix (docs/benchmarks/accuracy_matrix.json): sim seeds 1-15,
// 7scenes, 7scenes-long, mulran, livox, kitti07, loops seeds 0-26 at 1 % and 1-13 at 2 % drift.
// All with translation + yaw alignment (the ARCHE protocol). The real data is read through
// COVOX_DATA_DIR (io::data_directory()); a missing dataset is skipped with a message.
// The real data is for research only (7-Scenes: Microsoft's terms; MulRan: its own terms; HKU-2:
// no license stated).
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "runner/bag_scan_source.h"
#include "benchmark/benchmark_report.h"
#include "cli/command_line.h"
#include "eval/constraint_evaluation.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "runner/dataset_scan_sources.h"
#include "runner/sim_scan_source.h"
#include "runner/slam_run.h"

namespace {

using namespace covox;

const char kUsage[] =
    "usage: benchmark_accuracy [options]\n"
    "  --device auto|cpu|cuda   (default auto)\n"
    "  --cases LIST             comma-separated: "
    "sim,bag,7scenes,7scenes-long,mulran,livox,kitti07,\n"
    "                           loops,\n"
    "                           or all: the whole matrix (default: sim and the real data that is\n"
    "                           available)\n"
    "  --sim-seeds LIST         seeds of the sim case (default 1)\n"
    "  --loop-seeds LIST        seeds of the loops case; 0: seed 1 without drift (default "
    "0,1,2,3,4,5)\n"
    "  --loop-drift-percent P   the loops case's odometry ends P % of the 1980 m off (default 1:\n"
    "                           about 20 m; real LiDAR or visual odometry: 0.5 to 2)\n"
    "  --bag FILE               flight bag of the bag case (default "
    "demo_output/flight_seed1_256col/flight.bag)\n"
    "  --data-dir DIR           shared data (default: COVOX_DATA_DIR or the build's default)\n"
    "  --config FILE.yaml       a configuration file applied over every case's settings (to\n"
    "                           compare a setting across the cases; its `ros` section is ignored)\n"
    "  --trajectories-dir DIR   also write each case's trajectories as TUM files there\n"
    "  --output FILE            report (default docs/benchmarks/accuracy.json; with --cases all\n"
    "                           docs/benchmarks/accuracy_matrix.json)\n";

struct CaseRun {
  std::string name;
  std::unique_ptr<tools::ScanSource> source;
  pipeline::SlamConfig config;
};

// A case as run_slam maps its input: the preset for the input's kind (tools::default_preset),
// on `device`, nothing else.
CaseRun shipped_case(const std::string& name, std::unique_ptr<tools::ScanSource> source,
                     Device device) {
  pipeline::SlamConfig config = pipeline::load_preset(tools::default_preset(*source));
  config.device = device;
  return {name, std::move(source), config};
}

// Comma-separated seeds (integers >= 0) of `option`.
std::vector<uint64_t> parse_seeds(const std::string& option, const std::string& seeds) {
  std::vector<uint64_t> list;
  for (size_t begin = 0; begin < seeds.size();) {
    const size_t end = std::min(seeds.find(',', begin), seeds.size());
    const std::string item = seeds.substr(begin, end - begin);
    if (item.empty() || item.size() > 9 ||
        item.find_first_not_of("0123456789") != std::string::npos) {
      throw Error(option + ": '" + item + "' is not a seed (comma-separated integers >= 0)");
    }
    list.push_back(std::stoull(item));
    begin = end + 1;
  }
  return list;
}

std::string seed_range(int first, int last) {
  std::string list;
  for (int seed = first; seed <= last; ++seed)
    list += (list.empty() ? "" : ",") + std::to_string(seed);
  return list;
}

// The simulated 200 s flight of `seed` at 256 columns, as run_slam --simulate flies it.
void add_sim_runs(const std::string& seeds, Device device, std::vector<CaseRun>* runs) {
  for (uint64_t seed : parse_seeds("--sim-seeds", seeds)) {
    sim::SimulationOptions options;
    options.seed = seed;
    options.flight.variation_seed = seed;
    options.lidar.columns = 256;
    runs->push_back(shipped_case("simulated flight seed " + std::to_string(seed),
                                 std::make_unique<tools::SimScanSource>(options, 0.5), device));
  }
}

// Whether the dataset folder exists; says that `name` is skipped otherwise.
bool dataset_present(const std::string& name, const std::string& folder) {
  if (std::filesystem::exists(folder)) return true;
  std::printf("skipping %s: no folder '%s'\n", name.c_str(), folder.c_str());
  return false;
}

// 7-Scenes redkitchen frames 0-599, where the camera returns to places it saw: drift seeds 1-5
// (seeds 4 and 5 were held out while the rgbd preset's verification was tuned) and no drift
// (odometry = reference), at run_slam's default pixel stride.
void add_kitchen_long_runs(const std::string& data_dir, Device device, std::vector<CaseRun>* runs) {
  const std::string folder = data_dir + "/7scenes-redkitchen-long";
  if (!dataset_present("7-Scenes redkitchen-long", folder)) return;
  for (int seed = 0; seed <= 5; ++seed) {
    tools::RgbdScanOptions options;
    options.drift_seed = seed == 0 ? 1 : static_cast<uint64_t>(seed);
    options.drift_scale = seed == 0 ? 0.0 : 1.0;
    const std::string name = seed == 0 ? "7-Scenes redkitchen-long no drift"
                                       : "7-Scenes redkitchen-long seed " + std::to_string(seed);
    runs->push_back(
        shipped_case(name, std::make_unique<tools::RgbdScanSource>(folder, options), device));
  }
}

// The lidar-scans KITTI 07 dump as keyframes 10 s apart (one submap each): no drift and seed 1.
void add_kitti_keyframe_runs(const std::string& data_dir, Device device,
                             std::vector<CaseRun>* runs) {
  const std::string folder = data_dir + "/lidar-scans/kitti_07_dump";
  if (!dataset_present("KITTI 07 keyframes", folder)) return;
  for (double scale : {0.0, 1.0}) {
    tools::LidarKeyframeScanOptions options;
    options.drift_scale = scale;
    runs->push_back(shipped_case(
        scale == 0.0 ? "KITTI 07 keyframes no drift" : "KITTI 07 keyframes seed 1",
        std::make_unique<tools::LidarKeyframeGraphScanSource>(folder, options), device));
  }
}

// The HKU-2 Livox keyframes as recorded and with the simulator's drift added to their odometry
// (at least kLivoxAddedDriftM at the end; the model's own rates give 1-2 m over the 103 s walk).
constexpr double kLivoxAddedDriftM = 0.5;

void add_livox_runs(const std::string& data_dir, Device device, std::vector<CaseRun>* runs) {
  const std::string folder = data_dir + "/livox-hku-2";
  if (!dataset_present("Livox HKU-2", folder)) return;
  for (uint64_t seed = 0; seed <= 5; ++seed) {
    tools::LidarKeyframeScanOptions options;
    options.drift_seed = seed;
    options.added_drift_m = seed == 0 ? 0.0 : kLivoxAddedDriftM;
    const std::string name =
        seed == 0 ? "Livox HKU-2 as recorded" : "Livox HKU-2 drift seed " + std::to_string(seed);
    runs->push_back(shipped_case(
        name, std::make_unique<tools::LidarKeyframeScanSource>(folder, options), device));
  }
}

// The loops case's flight: two laps of a figure 8 twice the default's length (990 m a lap, its
// crossing in the open), 256 columns, the odometry drift_percent % of the distance off at the end
// (1 %: about 20 m, so the second lap passes the first's places 10-30 m from where the odometry
// puts them, beyond the registration's search); drift_percent 0: the same flight with the
// odometry equal to the truth.
constexpr double kLoopLobeHalfLengthM = 110.0;

std::unique_ptr<tools::ScanSource> loop_flight(uint64_t seed, double drift_percent) {
  sim::SimulationOptions options;
  options.seed = seed;
  options.flight.variation_seed = seed;
  options.lidar.columns = 256;
  options.flight.lobe_half_length_m = kLoopLobeHalfLengthM;
  options.flight.path_length_m = 2.0 * 9.0 * kLoopLobeHalfLengthM;
  if (drift_percent > 0.0) {
    options.drift.final_drift_percent = drift_percent;
  } else {
    options.drift_scale = 0.0;
  }
  return std::make_unique<tools::SimScanSource>(options, 0.5);
}

void add_loop_runs(const std::string& seeds, double drift_percent, Device device,
                   std::vector<CaseRun>* runs) {
  if (!(drift_percent > 0.0 && drift_percent <= 10.0)) {
    char message[96];
    std::snprintf(message, sizeof(message), "--loop-drift-percent must be in (0, 10], got %g",
                  drift_percent);
    throw Error(message);
  }
  for (uint64_t seed : parse_seeds("--loop-seeds", seeds)) {
    if (seed > 0) {
      char name[96];
      std::snprintf(name, sizeof(name), "simulated loops seed %llu, %g %% drift",
                    static_cast<unsigned long long>(seed), drift_percent);
      runs->push_back(shipped_case(name, loop_flight(seed, drift_percent), device));
      continue;
    }
    runs->push_back(shipped_case("simulated loops no drift", loop_flight(1, 0.0), device));
  }
}

// What to run: the --cases list and the seeds of the simulated cases.
struct Selection {
  std::string cases;  // empty: sim and the real data; "all": the whole matrix
  std::string sim_seeds, loop_seeds;
  double loop_drift_percent = 1.0;
  std::string bag_path, data_dir;
};

const char* const kCaseNames[] = {"sim",    "bag",   "7scenes", "7scenes-long",
                                  "mulran", "livox", "kitti07", "loops"};

// Throws covox::Error naming the first item of `cases` that is no case.
void check_case_names(const std::string& cases) {
  if (cases.empty() || cases == "all") return;
  for (size_t begin = 0; begin <= cases.size();) {
    const size_t end = std::min(cases.find(',', begin), cases.size());
    const std::string item = cases.substr(begin, end - begin);
    bool known = false;
    for (const char* name : kCaseNames) known = known || item == name;
    if (!known) {
      throw Error("--cases: '" + item +
                  "' is no case (sim, bag, 7scenes, 7scenes-long, mulran, livox, kitti07, "
                  "loops, or all)");
    }
    begin = end + 1;
  }
}

bool wanted(const Selection& selection, const std::string& name) {
  const std::string& cases = selection.cases;
  return cases.empty() || cases == "all" ||
         ("," + cases + ",").find("," + name + ",") != std::string::npos;
}

// A dataset folder's case when the folder exists; a message otherwise.
void add_if_present(const std::string& name, const std::string& folder,
                    const std::function<std::unique_ptr<tools::ScanSource>()>& open, Device device,
                    std::vector<CaseRun>* runs) {
  if (dataset_present(name, folder)) runs->push_back(shipped_case(name, open(), device));
}

// The cases asked for whose inputs exist, each as run_slam maps it; a missing input is skipped
// with a message.
std::vector<CaseRun> collect_runs(const Selection& selection, Device device) {
  const bool matrix = selection.cases == "all";
  std::vector<CaseRun> runs;
  if (wanted(selection, "sim"))
    add_sim_runs(matrix ? seed_range(1, 15) : selection.sim_seeds, device, &runs);
  if (!selection.cases.empty() && !matrix && wanted(selection, "bag")) {
    add_if_present(
        "flight bag", selection.bag_path,
        [&] {
          return std::make_unique<tools::BagScanSource>(selection.bag_path,
                                                        tools::BagScanOptions());
        },
        device, &runs);
  }
  const std::string kitchen = selection.data_dir + "/7scenes-redkitchen";
  if (wanted(selection, "7scenes")) {
    add_if_present(
        "7-Scenes redkitchen", kitchen,
        [&] {
          tools::RgbdScanOptions options;
          options.pixel_stride = 4;
          return std::make_unique<tools::RgbdScanSource>(kitchen, options);
        },
        device, &runs);
  }
  if (wanted(selection, "7scenes-long")) add_kitchen_long_runs(selection.data_dir, device, &runs);
  const std::string riverside = selection.data_dir + "/mulran-riverside02";
  if (wanted(selection, "mulran")) {
    add_if_present(
        "MulRan Riverside02", riverside,
        [&] {
          return std::make_unique<tools::LidarKeyframeScanSource>(
              riverside, tools::LidarKeyframeScanOptions());
        },
        device, &runs);
  }
  if (wanted(selection, "livox")) add_livox_runs(selection.data_dir, device, &runs);
  if (wanted(selection, "kitti07")) add_kitti_keyframe_runs(selection.data_dir, device, &runs);
  // Long flights (minutes each on a GPU, tens of minutes on the CPU): only when named.
  if (matrix) {
    add_loop_runs(seed_range(0, 26), 1.0, device, &runs);
    add_loop_runs(seed_range(1, 13), 2.0, device, &runs);
  } else if (!selection.cases.empty() && wanted(selection, "loops")) {
    add_loop_runs(selection.loop_seeds, selection.loop_drift_percent, device, &runs);
  }
  return runs;
}

// A registration constraint further than this from the reference relative pose is wrong.
constexpr double kWrongConstraintM = 0.1;
constexpr double kWrongConstraintRad = 5.0 * 3.14159265358979323846 / 180.0;

// Place recognition's closures against the truth (none when it is off): rows, and the count of
// wrong ones.
int64_t report_closures(const CaseRun& run, const tools::SlamRunResult& result,
                        tools::BenchmarkReport* report) {
  if (run.source->reference_kind() != tools::ReferenceKind::kGroundTruth) {
    return 0;
  }
  const eval::ConstraintEvaluation constraints = eval::evaluate_registration_constraints(
      run.source->reference(), result.submaps, result.constraints, kWrongConstraintM,
      kWrongConstraintRad);
  eval::print_closure_evaluation(constraints, stdout);
  const pipeline::PlaceRecognitionCounts& counts = result.counters.place_recognition;
  report->add(run.name, "place recognition candidates", static_cast<double>(counts.candidates), "");
  report->add(run.name, "loop closures accepted", static_cast<double>(counts.accepted), "");
  report->add(run.name, "loop closures wrong by > 1 m or 5 deg",
              static_cast<double>(constraints.wrong_closures), "");
  return constraints.wrong_closures;
}

// One case: run, print, add its rows to `report`, and write its trajectories when asked. Returns
// the number of wrong loop closures.
int64_t run_case(CaseRun& run, const std::string& trajectories_dir,
                 tools::BenchmarkReport* report) {
  std::printf("\n== %s: %s\n", run.name.c_str(), run.source->describe().c_str());
  std::fflush(stdout);
  const tools::SlamRunResult result =
      tools::run_slam_system(*run.source, run.config, tools::SlamRunOptions());
  tools::print_slam_run(result, stdout);
  // Keyframes 0.76 s apart: the association tolerance must span one keyframe gap.
  const tools::SlamRunEvaluation evaluation =
      tools::evaluate_slam_run(*run.source, result, eval::AlignmentMode::kTranslationYaw, 1.0);
  const bool truth = run.source->reference_kind() == tools::ReferenceKind::kGroundTruth;
  const std::string metric = truth ? "ATE RMSE" : "distance to reference RMSE";
  report->add(run.name, "scans", static_cast<double>(result.scans_given), "");
  // The float setting, rounded back to the decimal it was given as.
  report->add(run.name, "voxel size", std::round(run.config.map.voxel_size_m * 1e6) / 1e6, "m");
  report->add(run.name, "submaps", static_cast<double>(result.submaps.size()), "");
  report->add(run.name, "registration constraints",
              static_cast<double>(result.counters.registration.accepted), "");
  report->add(run.name, "real-time factor", result.real_time_factor(), "x");
  if (auto* rgbd = dynamic_cast<tools::RgbdScanSource*>(run.source.get())) {
    report->add(run.name, "odometry final drift", rgbd->final_drift_m(), "m");
    // True poses: every registration constraint against the reference.
    const eval::ConstraintEvaluation constraints = eval::evaluate_registration_constraints(
        run.source->reference(), result.submaps, result.constraints, kWrongConstraintM,
        kWrongConstraintRad);
    report->add(run.name, "registrations wrong by > 0.1 m or 5 deg",
                static_cast<double>(constraints.wrong), "");
    report->add(run.name, "registration max error", constraints.max_error_m, "m");
  }
  if (auto* keyframes = dynamic_cast<tools::KeyframeFolderScanSource*>(run.source.get()))
    report->add(run.name, "odometry added drift", keyframes->final_drift_m(), "m");
  if (auto* simulated = dynamic_cast<tools::SimScanSource*>(run.source.get())) {
    const auto& truth = simulated->mission().truth();
    const auto& odometry = simulated->mission().odometry();
    report->add(run.name, "odometry final drift",
                truth.empty()
                    ? 0.0
                    : (truth.back().pose.translation() - odometry.back().pose.translation()).norm(),
                "m");
  }
  const int64_t wrong_closures = report_closures(run, result, report);
  const tools::TrajectoryShift shift = tools::trajectory_shift(result);
  report->add(run.name, "shift from odometry RMS", shift.rms_m, "m");
  if (evaluation.available) {
    std::printf("%s (translation + yaw alignment, %zu poses): odometry %.3f m, covoxslam %.3f m\n",
                metric.c_str(), evaluation.corrected.aligned.size(),
                evaluation.odometry.absolute_position_m.rmse,
                evaluation.corrected.absolute_position_m.rmse);
    report->add(run.name, metric + " odometry", evaluation.odometry.absolute_position_m.rmse, "m");
    report->add(run.name, metric + " covoxslam", evaluation.corrected.absolute_position_m.rmse,
                "m");
    report->add(run.name, "max error covoxslam", evaluation.corrected.absolute_position_m.max, "m");
  } else {
    std::printf("no evaluation: %s\n", evaluation.problem.c_str());
  }
  if (!trajectories_dir.empty()) {
    std::filesystem::create_directories(trajectories_dir);
    std::string stem = run.name;
    for (char& c : stem) c = std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
    io::write_tum_trajectory(trajectories_dir + "/" + stem + "_covoxslam.tum", result.corrected);
    io::write_tum_trajectory(trajectories_dir + "/" + stem + "_odometry.tum", result.odometry);
    io::write_tum_trajectory(trajectories_dir + "/" + stem + "_reference.tum",
                             run.source->reference());
  }
  return wrong_closures;
}

// `path` applied over every run's settings (pipeline::load_slam_config), the device kept.
void apply_config_file(const std::string& path, std::vector<CaseRun>* runs) {
  for (CaseRun& run : *runs) {
    const Device device = run.config.device;
    const pipeline::SlamConfigFileUse use = pipeline::load_slam_config(path, &run.config);
    run.config.device = device;
    if (&run == &runs->front()) {
      std::printf("config: %s (%zu SLAM parameters over every case)\n", path.c_str(), use.applied);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  const std::string device_text = args.text("--device", "auto");
  Selection selection;
  selection.cases = args.text("--cases", "");
  selection.sim_seeds = args.text("--sim-seeds", "1");
  selection.loop_seeds = args.text("--loop-seeds", "0,1,2,3,4,5");
  selection.loop_drift_percent = args.number("--loop-drift-percent", 1.0, 0.0, 100.0);
  selection.bag_path = args.text("--bag", "demo_output/flight_seed1_256col/flight.bag");
  selection.data_dir = args.text("--data-dir", io::data_directory());
  const std::string trajectories_dir = args.text("--trajectories-dir", "");
  const std::string output =
      args.output_file("--output", selection.cases == "all" ? "docs/benchmarks/accuracy_matrix.json"
                                                            : "docs/benchmarks/accuracy.json");
  const std::string config_path = args.text("--config", "");
  args.finish();

  try {
    check_case_names(selection.cases);
    const Device device = select_device(parse_device_request(device_text));
    tools::BenchmarkReport report("accuracy", describe_device(device), argc, argv);
    std::vector<CaseRun> runs = collect_runs(selection, device);
    if (runs.empty()) throw Error("no case to run (see the messages above)");
    if (!config_path.empty()) apply_config_file(config_path, &runs);
    int64_t wrong_closures = 0;
    for (CaseRun& run : runs) wrong_closures += run_case(run, trajectories_dir, &report);
    std::printf("\n");
    report.print_table(std::cout);
    report.write_json(output);
    std::printf("report -> %s\n", output.c_str());
    if (wrong_closures > 0) {
      std::fprintf(stderr, "benchmark_accuracy: %lld loop closures join the wrong places\n",
                   static_cast<long long>(wrong_closures));
      return 2;
    }
  } catch (const Error& error) {
    std::cerr << "benchmark_accuracy: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

// Pose-graph solve time: covoxslam's LM + PCG on the GPU and on the CPU twin, and Ceres
// (SPARSE_SCHUR, 4 threads: voxgraph's setting) on the same problems. Prints a table and writes
// docs/benchmarks/backend.json.
//
//   benchmark_backend [--device all|cuda|cpu] [--submaps 50,200,1000] [--repeats 3]
//                     [--ceres-repeats 1] [--ceres-time-limit-s 300] [--data DIR]
//                     [--skip-ceres] [--skip-garage] [--skip-registration] [--relative-graphs]
//                     [--preconditioner block-jacobi|chain|both] [--distinct-submaps 12]
//                     [--lidar-columns 1024] [--points-per-submap 2000]
//                     [--registration-distance tsdf|esdf] [--pcg-tolerance T]
//                     [--pcg-max-iterations N] [--chain-segment 64] [--registration-sigma 0.1]
//                     [--output PATH]
//
// Cases:
//  * registration graphs: n submaps of a street with odometry between consecutive ones and
//    dense registration terms k -> k+1, k -> k+2, k+1 -> k (Huber), about
//    points-per-submap points per term, each an ESDF/TSDF lookup with trilinear interpolation and
//    Jacobians w.r.t. both poses (benchmark/registration_benchmark_world.h: distinct-submaps real
//    submaps whose fields are reused along a periodic street, because building a thousand real
//    submaps is too slow on a small CPU);
//  * pose-graphs/parking-garage.g2o in SE(3) mode;
//  * with --relative-graphs, the synthetic relative-pose-only graphs (odometry, loop closures,
//    height constraints) of synthetic_pose_graph.h.
// Every solver starts from the same initial guess and runs with its default stopping rules
// (relative function tolerance 1e-6); the final cost (and, for the registration graphs, the
// position RMSE against the truth) is reported next to the time so the comparison can be judged.
// Ceres is bounded by --ceres-time-limit-s per solve (its report then says NO_CONVERGENCE).
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "benchmark/benchmark_report.h"
#include "covoxslam/backend/ceres_pose_graph_oracle.h"
#include "covoxslam/backend/ceres_registration_oracle.h"
#include "covoxslam/backend/g2o_reader.h"
#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/synthetic_pose_graph.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/atomic_file.h"
#include "covoxslam/io/data_directory.h"
#include "benchmark/registration_benchmark_world.h"

namespace covox {
namespace {

struct Options {
  std::string device = "all";
  std::vector<int> submaps = {50, 200, 1000};
  int repeats = 3;
  int ceres_repeats = 1;
  double ceres_time_limit_s = 300.0;
  std::string data;
  bool skip_ceres = false;
  bool skip_garage = false;
  bool skip_registration = false;
  bool relative_graphs = false;
  std::vector<backend::PcgPreconditioner> preconditioners = {
      backend::PcgPreconditioner::kBlockJacobi, backend::PcgPreconditioner::kOdometryChain};
  tools::RegistrationWorldConfig world;
  backend::RegistrationDistance distance = backend::RegistrationDistance::kTsdfNearSurface;
  backend::PoseGraphSolverOptions solver;  // our solver's settings (defaults unless overridden)
  // Registration residual noise: 0.1 lets the registration terms outweigh the odometry (with 1
  // the solution barely leaves the odometry), as voxgraph's registration weights do.
  double registration_sigma = 0.1;
  std::string output;
};

[[noreturn]] void usage_error(const std::string& message) {
  std::cerr
      << "benchmark_backend: " << message << "\n"
      << "usage: benchmark_backend [--device all|cuda|cpu] [--submaps 50,200,1000] [--repeats 3]\n"
      << "                         [--ceres-repeats 1] [--ceres-time-limit-s 300] [--data DIR]\n"
      << "                         [--skip-ceres] [--skip-garage] [--skip-registration] "
         "[--relative-graphs]\n"
      << "                         [--preconditioner block-jacobi|chain|both] [--distinct-submaps "
         "12]\n"
      << "                         [--lidar-columns 1024] [--points-per-submap 2000]\n"
      << "                         [--registration-distance tsdf|esdf] [--pcg-tolerance T]\n"
      << "                         [--pcg-max-iterations N] [--chain-segment 64] "
         "[--registration-sigma 0.1]\n"
      << "                         [--output PATH]\n";
  std::exit(2);
}

int positive_int(const std::string& flag, const std::string& text, int minimum) {
  char* end = nullptr;
  const long value = std::strtol(text.c_str(), &end, 10);
  if (end == text.c_str() || *end != '\0' || value < minimum) {
    usage_error(flag + " must be an integer >= " + std::to_string(minimum) + ", got '" + text +
                "'");
  }
  return static_cast<int>(value);
}

// The --preconditioner choices: one of them, or both for a side-by-side comparison.
std::vector<backend::PcgPreconditioner> preconditioners_of(const std::string& name) {
  if (name == "block-jacobi") return {backend::PcgPreconditioner::kBlockJacobi};
  if (name == "chain") return {backend::PcgPreconditioner::kOdometryChain};
  if (name == "both") {
    return {backend::PcgPreconditioner::kBlockJacobi, backend::PcgPreconditioner::kOdometryChain};
  }
  usage_error("--preconditioner must be block-jacobi, chain or both, got '" + name + "'");
}

backend::RegistrationDistance distance_of(const std::string& name) {
  if (name == "tsdf") return backend::RegistrationDistance::kTsdfNearSurface;
  if (name == "esdf") return backend::RegistrationDistance::kEsdf;
  usage_error("--registration-distance must be tsdf or esdf, got '" + name + "'");
}

std::vector<int> submap_counts(const std::string& flag, const std::string& text) {
  std::vector<int> counts;
  std::stringstream list(text);
  for (std::string item; std::getline(list, item, ',');)
    counts.push_back(positive_int(flag, item, 3));
  return counts;
}

double positive_number(const std::string& flag, const std::string& text) {
  const double value = std::atof(text.c_str());
  if (!(value > 0.0)) usage_error(flag + " must be positive");
  return value;
}

// One command-line option: its name, whether a value follows it, and how it sets Options (from
// the value, empty for a switch).
struct OptionRule {
  const char* name;
  bool takes_value;
  void (*apply)(Options& o, const std::string& flag, const std::string& value);
};

const OptionRule kOptionRules[] = {
    {"--device", true, [](Options& o, const std::string&, const std::string& v) { o.device = v; }},
    {"--submaps", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.submaps = submap_counts(f, v);
     }},
    {"--repeats", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.repeats = positive_int(f, v, 1);
     }},
    {"--ceres-repeats", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.ceres_repeats = positive_int(f, v, 1);
     }},
    {"--ceres-time-limit-s", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.ceres_time_limit_s = positive_number(f, v);
     }},
    {"--data", true, [](Options& o, const std::string&, const std::string& v) { o.data = v; }},
    {"--skip-ceres", false,
     [](Options& o, const std::string&, const std::string&) { o.skip_ceres = true; }},
    {"--skip-garage", false,
     [](Options& o, const std::string&, const std::string&) { o.skip_garage = true; }},
    {"--skip-registration", false,
     [](Options& o, const std::string&, const std::string&) { o.skip_registration = true; }},
    {"--relative-graphs", false,
     [](Options& o, const std::string&, const std::string&) { o.relative_graphs = true; }},
    {"--preconditioner", true,
     [](Options& o, const std::string&, const std::string& v) {
       o.preconditioners = preconditioners_of(v);
     }},
    {"--distinct-submaps", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.world.distinct_submaps = positive_int(f, v, 3);
     }},
    {"--lidar-columns", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.world.lidar_columns = positive_int(f, v, 16);
     }},
    {"--points-per-submap", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.world.points_per_submap = positive_int(f, v, 10);
     }},
    {"--pcg-tolerance", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.solver.pcg_relative_tolerance = positive_number(f, v);
     }},
    {"--registration-sigma", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.registration_sigma = positive_number(f, v);
     }},
    {"--chain-segment", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.solver.chain_segment_vertices = positive_int(f, v, 0);
     }},
    {"--pcg-max-iterations", true,
     [](Options& o, const std::string& f, const std::string& v) {
       o.solver.pcg_max_iterations = positive_int(f, v, 1);
     }},
    {"--registration-distance", true,
     [](Options& o, const std::string&, const std::string& v) { o.distance = distance_of(v); }},
    {"--output", true,
     [](Options& o, const std::string& f, const std::string& v) {
       try {
         io::probe_output_path(v);  // before the benchmark runs, not after
       } catch (const Error& error) {
         usage_error(f + " " + v + ": " + error.what());
       }
       o.output = v;
     }},
};

// Options are applied in command-line order, so a repeated option's last value wins.
Options parse(int argc, char** argv) {
  Options o;
  o.data = io::data_directory();
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const OptionRule* rule = nullptr;
    for (const OptionRule& candidate : kOptionRules) {
      if (arg == candidate.name) rule = &candidate;
    }
    if (rule == nullptr) usage_error("unknown argument '" + arg + "'");
    std::string value;
    if (rule->takes_value) {
      if (i + 1 >= argc) usage_error(arg + " needs a value");
      value = argv[++i];
    }
    rule->apply(o, arg, value);
  }
  return o;
}

std::vector<Device> devices_of(const std::string& name) {
  if (name == "all") return available_devices();
  return {select_device(parse_device_request(name))};
}

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

// Our solver on one device and preconditioner: `solve(graph, options)` solves a fresh copy.
template <class Graph, class Solve>
Graph run_ours(const std::string& label, const Graph& initial,
               backend::PcgPreconditioner preconditioner, const Options& o, Solve solve,
               tools::BenchmarkReport* report) {
  std::vector<double> times;
  backend::PoseGraphSolverSummary summary;
  Graph graph;
  for (int r = 0; r < o.repeats; ++r) {
    graph = initial;
    backend::PoseGraphSolverOptions options = o.solver;
    options.preconditioner = preconditioner;
    summary = solve(&graph, options);
    times.push_back(summary.solve_time_s * 1e3);
  }
  std::cerr << label << ": " << summary.report() << "\n";
  report->add(label, "solve time (median)", median(times), "ms");
  report->add(label, "final cost", summary.final_cost, "");
  report->add(label, "LM iterations", summary.iterations, "");
  report->add(label, "PCG iterations", static_cast<double>(summary.pcg_iterations), "");
  return graph;
}

#if COVOX_HAVE_CERES
backend::ceres_oracle::OracleOptions voxgraph_ceres_options(const Options& o) {
  backend::ceres_oracle::OracleOptions ceres;
  ceres.linear_solver = ceres::SPARSE_SCHUR;
  ceres.threads = 4;
  // Ceres' defaults, as voxgraph uses them.
  ceres.max_iterations = 50;
  ceres.function_tolerance = 1e-6;
  ceres.gradient_tolerance = 1e-10;
  ceres.parameter_tolerance = 1e-8;
  ceres.max_solver_time_s = o.ceres_time_limit_s;
  return ceres;
}

template <class Graph, class Solve>
Graph run_ceres(const std::string& label, const Graph& initial, const Options& o, Solve solve,
                tools::BenchmarkReport* report) {
  std::vector<double> times;
  backend::ceres_oracle::OracleResult result;
  Graph graph;
  for (int r = 0; r < o.ceres_repeats; ++r) {
    graph = initial;
    result = solve(&graph, voxgraph_ceres_options(o));
    times.push_back(result.solve_time_s * 1e3);
  }
  std::cerr << label << ": " << result.brief_report << " (time limit " << o.ceres_time_limit_s
            << " s)\n";
  report->add(label, "solve time (median)", median(times), "ms");
  report->add(label, "final cost", result.final_cost, "");
  report->add(label, "LM iterations", result.iterations, "");  // Ceres counts iteration 0 too
  return graph;
}
#endif

template <class Graph>
void run_pose_graph_case(const std::string& name, const Graph& initial,
                         const std::vector<Device>& devices, const Options& o,
                         tools::BenchmarkReport* report) {
  for (const Device device : devices) {
    for (const backend::PcgPreconditioner preconditioner : o.preconditioners) {
      run_ours(
          name + " " + to_string(device) + " " + backend::to_string(preconditioner), initial,
          preconditioner, o,
          [&](Graph* g, const backend::PoseGraphSolverOptions& options) {
            return backend::solve_pose_graph(g, device, options);
          },
          report);
    }
  }
#if COVOX_HAVE_CERES
  if (!o.skip_ceres) {
    run_ceres(
        name + " ceres SPARSE_SCHUR x4", initial, o,
        [](Graph* g, const backend::ceres_oracle::OracleOptions& options) {
          return backend::ceres_oracle::solve(g, options);
        },
        report);
  }
#endif
}

void run_registration_cases(const std::vector<Device>& devices, const Options& o,
                            tools::BenchmarkReport* report) {
  std::map<Device, tools::RegistrationWorld> worlds;
  for (const Device device : devices) {
    worlds.emplace(device, tools::build_registration_world(o.world, device));
    const tools::RegistrationWorld& w = worlds.at(device);
    int64_t points = 0;
    for (const auto& p : w.points) points += static_cast<int64_t>(p->points.size());
    std::cerr << "registration world on " << to_string(device) << ": " << w.maps.size()
              << " distinct submaps (period " << w.period_m << " m), "
              << points / static_cast<int64_t>(w.points.size())
              << " registration points per submap on average, built in " << w.build_time_s
              << " s\n";
  }
  for (const int n : o.submaps) {
    tools::RegistrationGraphOptions graph_options;
    graph_options.submaps = n;
    graph_options.distance = o.distance;
    graph_options.residual_sigma = o.registration_sigma;
    std::string name;
    for (const Device device : devices) {
      const tools::RegistrationGraph problem =
          tools::make_registration_graph(worlds.at(device), graph_options);
      int64_t points = 0;
      for (const auto& t : problem.terms) points += static_cast<int64_t>(t.points_i->points.size());
      name = "reg n=" + std::to_string(n) + " (" + std::to_string(problem.terms.size()) +
             " pairs, " + std::to_string(points / 1000) + "k points)";
      if (device == devices.front()) {
        report->add(name + " initial", "position RMSE",
                    tools::position_rmse_m(problem.graph.poses, problem.truth), "m");
        // Where the truth sits on the objective: a final cost below it means the registration
        // terms' optimum is biased away from the truth (single-scan submaps), not a failed solve.
        backend::PoseGraph4Dof at_truth = problem.graph;
        at_truth.poses = problem.truth;
        report->add(name + " truth", "final cost",
                    backend::pose_graph_cost(at_truth) +
                        backend::registration_terms_cost(at_truth, problem.terms),
                    "");
      }
      for (const backend::PcgPreconditioner preconditioner : o.preconditioners) {
        const std::string label =
            name + " " + to_string(device) + " " + backend::to_string(preconditioner);
        const backend::PoseGraph4Dof solved = run_ours(
            label, problem.graph, preconditioner, o,
            [&](backend::PoseGraph4Dof* g, const backend::PoseGraphSolverOptions& options) {
              return backend::solve_pose_graph(g, problem.terms, device, options);
            },
            report);
        report->add(label, "position RMSE", tools::position_rmse_m(solved.poses, problem.truth),
                    "m");
      }
    }
#if COVOX_HAVE_CERES
    if (!o.skip_ceres) {
      // Ceres runs on the host: it reads the first device's world (host copies of device maps).
      const tools::RegistrationGraph problem =
          tools::make_registration_graph(worlds.at(devices.front()), graph_options);
      backend::ceres_oracle::HostRegistrationFields fields;
      const std::string label = name + " ceres SPARSE_SCHUR x4";
      const backend::PoseGraph4Dof solved = run_ceres(
          label, problem.graph, o,
          [&](backend::PoseGraph4Dof* g, const backend::ceres_oracle::OracleOptions& options) {
            return backend::ceres_oracle::solve(g, problem.terms, options, &fields);
          },
          report);
      report->add(label, "position RMSE", tools::position_rmse_m(solved.poses, problem.truth), "m");
    }
#endif
  }
}

int run(int argc, char** argv) {
  const Options o = parse(argc, argv);
  const std::vector<Device> devices = devices_of(o.device);
  std::string description;
  for (const Device d : devices)
    description += (description.empty() ? "" : "; ") + describe_device(d);
#if COVOX_HAVE_CERES
  if (!o.skip_ceres)
    description += "; Ceres " + std::string(CERES_VERSION_STRING) + " SPARSE_SCHUR, 4 threads";
#else
  std::cerr << "benchmark_backend: built without Ceres: no Ceres rows (run the Ceres part on a "
               "machine with it)\n";
#endif
  tools::BenchmarkReport report("backend", description, argc, argv);
  if (!o.skip_registration) run_registration_cases(devices, o, &report);
  if (o.relative_graphs) {
    for (const int n : o.submaps) {
      backend::SyntheticGraphOptions synthetic;
      synthetic.submaps = n;
      synthetic.height_constraints = true;
      const auto problem = backend::make_synthetic_graph_4dof(synthetic);
      run_pose_graph_case("4dof n=" + std::to_string(n) + " (" +
                              std::to_string(problem.graph.constraints.size()) + " constraints)",
                          problem.graph, devices, o, &report);
    }
  }
  if (!o.skip_garage) {
    const std::string path = o.data + "/pose-graphs/parking-garage.g2o";
    if (std::filesystem::exists(path)) {
      run_pose_graph_case("parking-garage se3", backend::read_g2o(path).graph, devices, o, &report);
    } else {
      std::cerr << "benchmark_backend: skipping parking-garage: " << path << " is missing\n";
    }
  }
  report.print_table(std::cout);
  report.write_json(o.output);
  return 0;
}

}  // namespace
}  // namespace covox

int main(int argc, char** argv) {
  try {
    return covox::run(argc, argv);
  } catch (const covox::Error& error) {
    std::cerr << "benchmark_backend: " << error.what() << "\n";
    return 1;
  }
}

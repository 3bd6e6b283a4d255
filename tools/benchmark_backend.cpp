// Pose-graph solve time: covoxslam's LM + PCG on the GPU and on the CPU twin, and Ceres
// (SPARSE_SCHUR, 4 threads: voxgraph's setting) on the same residuals. Prints a table and writes
// docs/benchmarks/backend.json.
//
//   benchmark_backend [--device all|cuda|cpu] [--submaps 50,200,1000] [--repeats 3]
//                     [--data DIR] [--skip-ceres] [--skip-garage] [--output PATH]
//                     [--preconditioner block-jacobi|chain]
//
// Cases: synthetic 4-DoF submap graphs (odometry plus up to 4 registration-like relative
// constraints per submap to nearby submaps, absolute height constraints), and
// pose-graphs/parking-garage.g2o in SE(3) mode. Every solver starts from the same initial guess
// and runs with its default stopping rules (relative function tolerance 1e-6); the final cost is
// reported next to the time so the comparison can be judged.
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "benchmark_report.h"
#include "covoxslam/backend/ceres_pose_graph_oracle.h"
#include "covoxslam/backend/g2o_reader.h"
#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/synthetic_pose_graph.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"

namespace covox {
namespace {

struct Options {
  std::string device = "all";
  std::vector<int> submaps = {50, 200, 1000};
  int repeats = 3;
  std::string data;
  bool skip_ceres = false;
  bool skip_garage = false;
  std::string output;
  backend::PcgPreconditioner preconditioner = backend::PcgPreconditioner::kBlockJacobi;
};

[[noreturn]] void usage_error(const std::string& message) {
  std::cerr << "benchmark_backend: " << message << "\n"
            << "usage: benchmark_backend [--device all|cuda|cpu] [--submaps 50,200,1000] [--repeats 3]\n"
            << "                         [--data DIR] [--skip-ceres] [--skip-garage] [--output PATH]\n"
            << "                         [--preconditioner block-jacobi|chain]\n";
  std::exit(2);
}

Options parse(int argc, char** argv) {
  Options o;
  o.data = io::data_directory();
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage_error(arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--device") {
      o.device = value();
    } else if (arg == "--submaps") {
      o.submaps.clear();
      std::stringstream list(value());
      for (std::string item; std::getline(list, item, ',');) {
        const int n = std::atoi(item.c_str());
        if (n < 2) usage_error("--submaps entries must be at least 2, got '" + item + "'");
        o.submaps.push_back(n);
      }
    } else if (arg == "--repeats") {
      o.repeats = std::atoi(value().c_str());
      if (o.repeats < 1) usage_error("--repeats must be at least 1");
    } else if (arg == "--data") {
      o.data = value();
    } else if (arg == "--skip-ceres") {
      o.skip_ceres = true;
    } else if (arg == "--skip-garage") {
      o.skip_garage = true;
    } else if (arg == "--preconditioner") {
      const std::string name = value();
      if (name == "block-jacobi") {
        o.preconditioner = backend::PcgPreconditioner::kBlockJacobi;
      } else if (name == "chain") {
        o.preconditioner = backend::PcgPreconditioner::kOdometryChain;
      } else {
        usage_error("--preconditioner must be block-jacobi or chain, got '" + name + "'");
      }
    } else if (arg == "--output") {
      o.output = value();
    } else {
      usage_error("unknown argument '" + arg + "'");
    }
  }
  return o;
}

std::vector<Device> devices_of(const std::string& name) {
  if (name == "all") return available_devices();
  return {select_device(parse_device_request(name))};
}

template <class Graph>
void run_case(const std::string& name, const Graph& initial, const std::vector<Device>& devices, const Options& o,
              tools::BenchmarkReport* report) {
  for (const Device device : devices) {
    std::vector<double> times;
    backend::PoseGraphSolverSummary summary;
    for (int r = 0; r < o.repeats; ++r) {
      Graph graph = initial;
      backend::PoseGraphSolverOptions options;
      options.preconditioner = o.preconditioner;
      summary = backend::solve_pose_graph(&graph, device, options);
      times.push_back(summary.solve_time_s * 1e3);
    }
    std::sort(times.begin(), times.end());
    const std::string label = name + " " + to_string(device) + " " + backend::to_string(o.preconditioner);
    std::cerr << label << ": " << summary.report() << "\n";
    report->add(label, "solve time (median)", times[times.size() / 2], "ms");
    report->add(label, "final cost", summary.final_cost, "");
    report->add(label, "LM iterations", summary.iterations, "");
    report->add(label, "PCG iterations", static_cast<double>(summary.pcg_iterations), "");
  }
#if COVOX_HAVE_CERES
  if (!o.skip_ceres) {
    backend::ceres_oracle::OracleOptions ceres;
    ceres.linear_solver = ceres::SPARSE_SCHUR;
    ceres.threads = 4;
    // Ceres' defaults, as voxgraph uses them.
    ceres.max_iterations = 50;
    ceres.function_tolerance = 1e-6;
    ceres.gradient_tolerance = 1e-10;
    ceres.parameter_tolerance = 1e-8;
    std::vector<double> times;
    backend::ceres_oracle::OracleResult result;
    for (int r = 0; r < o.repeats; ++r) {
      Graph graph = initial;
      result = backend::ceres_oracle::solve(&graph, ceres);
      times.push_back(result.solve_time_s * 1e3);
    }
    std::sort(times.begin(), times.end());
    const std::string label = name + " ceres SPARSE_SCHUR x4";
    std::cerr << label << ": " << result.brief_report << "\n";
    report->add(label, "solve time (median)", times[times.size() / 2], "ms");
    report->add(label, "final cost", result.final_cost, "");
    report->add(label, "LM iterations", result.iterations, "");  // Ceres counts iteration 0 too
  }
#else
  (void)o;
#endif
}

int run(int argc, char** argv) {
  const Options o = parse(argc, argv);
  const std::vector<Device> devices = devices_of(o.device);
  std::string description;
  for (const Device d : devices) description += (description.empty() ? "" : "; ") + describe_device(d);
  tools::BenchmarkReport report("backend", description, argc, argv);
  for (const int n : o.submaps) {
    backend::SyntheticGraphOptions synthetic;
    synthetic.submaps = n;
    synthetic.height_constraints = true;
    const auto problem = backend::make_synthetic_graph_4dof(synthetic);
    run_case("4dof n=" + std::to_string(n) + " (" + std::to_string(problem.graph.constraints.size()) + " constraints)",
             problem.graph, devices, o, &report);
  }
  if (!o.skip_garage) {
    const std::string path = o.data + "/pose-graphs/parking-garage.g2o";
    if (std::filesystem::exists(path)) {
      run_case("parking-garage se3", backend::read_g2o(path).graph, devices, o, &report);
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

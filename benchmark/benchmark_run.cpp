#include "benchmark/benchmark_run.h"

#include <exception>
#include <iostream>

#include "covoxslam/core/error.h"

namespace covox {
namespace tools {

void publish_reports(const std::vector<const BenchmarkReport*>& reports,
                     const std::string& json_path) {
  if (reports.size() > 1 && !json_path.empty()) {
    throw Error("publish_reports: one JSON path for " + std::to_string(reports.size()) +
                " reports");
  }
  for (const BenchmarkReport* report : reports) report->print_table(std::cout);
  std::string written;
  for (const BenchmarkReport* report : reports) {
    report->write_json(json_path);
    written += (written.empty() ? "" : " and ") +
               (json_path.empty() ? report->default_json_path() : json_path);
  }
  std::cout << "wrote " << written << std::endl;
}

int run_benchmark(const char* tool_name, const std::function<void()>& body) {
  try {
    body();
  } catch (const std::exception& error) {
    std::cerr << tool_name << ": " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

}  // namespace tools
}  // namespace covox

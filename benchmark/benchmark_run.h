#pragma once
// What every benchmark's main() does around its measurements: time work on a stream, publish the
// reports (tables on stdout, JSON files) and turn an exception into a message and exit code 1.
//   int main(int argc, char** argv) {
//     const Options options = parse(argc, argv);
//     return tools::run_benchmark("benchmark_tsdf", [&] {
//       tools::BenchmarkReport report("tsdf", ..., argc, argv);
//       report.add(name, "integration", tools::stream_milliseconds(stream, [&] { ... }), "ms");
//       tools::publish_reports({&report}, options.output);
//     });
//   }
#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "benchmark/benchmark_report.h"
#include "covoxslam/core/stream.h"

namespace covox {
namespace tools {

// Wall-clock milliseconds of `work` on `stream`. The stream is drained before the clock starts and
// before it stops, so that queued device work is neither charged to `work` nor hidden from it.
template <class Work>
double stream_milliseconds(const Stream& stream, Work&& work) {
  stream.synchronize();
  const auto start = std::chrono::steady_clock::now();
  work();
  stream.synchronize();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

// Prints every report's table, then writes each report's JSON and says where ("wrote A and B").
// `json_path` names the file of a single report (empty: its default path); with several reports
// it must be empty (each goes to its default path).
void publish_reports(const std::vector<const BenchmarkReport*>& reports,
                     const std::string& json_path = std::string());

// main()'s exit code for a benchmark: 0 when `body` returns; when it throws, prints
// "<tool_name>: <what>" to stderr and returns 1.
int run_benchmark(const char* tool_name, const std::function<void()>& body);

}  // namespace tools
}  // namespace covox

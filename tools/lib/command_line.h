#pragma once
// The small command-line parser every tool shares: `--name value` options and `--name` switches,
// unknown options and bad values reported with the tool's usage text (exit code 2), so each tool
// states only its options and defaults.
//
//   tools::CommandLine args(argc, argv, "usage: benchmark_tsdf [--device all|cuda|cpu] ...");
//   const std::string device = args.text("--device", "all");
//   const int64_t count = args.integer("--integrations", 100);
//   args.finish();  // any option not asked for is an error
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "covoxslam/core/device.h"

namespace covox {
namespace tools {

class CommandLine {
 public:
  CommandLine(int argc, const char* const* argv, std::string usage);

  std::string text(const std::string& name, const std::string& fallback);
  int64_t integer(const std::string& name, int64_t fallback);
  // integer(), and fails with "<name> must be positive" unless the value is > 0.
  int64_t positive_integer(const std::string& name, int64_t fallback);
  double number(const std::string& name, double fallback);
  // Comma-separated numbers, e.g. "--load-factors 0.5,0.7,0.85".
  std::vector<double> numbers(const std::string& name, const std::vector<double>& fallback);
  // A switch without a value.
  bool flag(const std::string& name);
  // Exits with the usage text if an option was given that no call above asked for.
  void finish() const;
  // Prints `problem` and the usage text to stderr and exits with code 2.
  [[noreturn]] void fail(const std::string& problem) const;

 private:
  const std::string* find_value(const std::string& name);
  std::string program_;
  std::string usage_;
  std::vector<std::string> arguments_;
  std::set<size_t> consumed_;
};

// The devices a benchmark runs on: "all" = every usable device, GPU first; otherwise one device
// chosen like everywhere else ("cuda", "cpu", "auto").
std::vector<Device> benchmark_devices(const std::string& request);
// "<GPU name>; CPU (<N> OpenMP threads)" for the report header.
std::string describe_devices(const std::vector<Device>& devices);

}  // namespace tools
}  // namespace covox

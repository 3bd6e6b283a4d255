#pragma once
// The small command-line parser every tool shares: `--name value` options and `--name` switches,
// unknown options and bad values reported with the tool's usage text (exit code 2), so each tool
// states only its options, defaults and bounds.
//
//   tools::CommandLine args(argc, argv, "usage: benchmark_tsdf [--device all|cuda|cpu] ...");
//   const std::string device = args.text("--device", "all");
//   const int64_t count = args.integer("--integrations", 100, 1, 1000000);
//   const std::string mesh = args.output_file("--mesh", "mesh.ply");
//   args.finish();  // any option not asked for is an error
#include <cstdint>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "covoxslam/core/device.h"

namespace covox {
namespace tools {

// Values are read strictly (io/setting_values.h): the whole text is the value, numbers are
// finite and decimal, integers fit, and a value outside the option's bounds is refused with the
// option's name and the accepted range. An option given twice is refused (which one was meant?),
// and so is a value that is itself an option (`--mesh --trajectory t.tum`). Output files are
// checked when they are read, before any work: their folder must exist and take a new file.
class CommandLine {
 public:
  // kThrow: fail() throws covox::Error instead of exiting (for tests).
  enum class OnFailure { kExit, kThrow };
  static constexpr int64_t kIntMin = std::numeric_limits<int>::min();
  static constexpr int64_t kIntMax = std::numeric_limits<int>::max();
  static constexpr double kAnyNumber = std::numeric_limits<double>::max();

  CommandLine(int argc, const char* const* argv, std::string usage,
              OnFailure on_failure = OnFailure::kExit);

  std::string text(const std::string& name, const std::string& fallback);
  // Bounds are inclusive; the defaults keep an integer within an int.
  int64_t integer(const std::string& name, int64_t fallback, int64_t minimum = kIntMin,
                  int64_t maximum = kIntMax);
  // integer() in [1, maximum].
  int64_t positive_integer(const std::string& name, int64_t fallback, int64_t maximum = kIntMax);
  // A finite number in [minimum, maximum]. The fallback is returned as it is (NaN may mean
  // "not given").
  double number(const std::string& name, double fallback, double minimum = -kAnyNumber,
                double maximum = kAnyNumber);
  // Comma-separated numbers, e.g. "--load-factors 0.5,0.7,0.85", each in [minimum, maximum].
  std::vector<double> numbers(const std::string& name, const std::vector<double>& fallback,
                              double minimum = -kAnyNumber, double maximum = kAnyNumber);
  // text() for a file the tool will write: unless empty, checked now (io::probe_output_path:
  // its folder exists and takes a new file, it is not a folder), failing with the option's name.
  std::string output_file(const std::string& name, const std::string& fallback);
  // A folder the tool will write files into: created with its parents and checked now (it takes
  // a new file), failing with the option's name.
  std::string output_folder(const std::string& name, const std::string& fallback);
  // A switch without a value.
  bool flag(const std::string& name);
  // Exits with the usage text if an option was given that no call above asked for.
  void finish() const;
  // Prints `problem` and the usage text to stderr and exits with code 2 (or throws, kThrow).
  [[noreturn]] void fail(const std::string& problem) const;

 private:
  const std::string* find_value(const std::string& name);
  // The index of `name` among the arguments (npos: not given); fails when given twice.
  size_t find_once(const std::string& name);
  std::string program_;
  std::string usage_;
  OnFailure on_failure_;
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

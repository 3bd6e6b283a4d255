#include "cli/command_line.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "covoxslam/core/error.h"
#include "covoxslam/io/atomic_file.h"
#include "covoxslam/io/setting_values.h"

namespace covox {
namespace tools {

namespace {

std::string range_text(double minimum, double maximum) {
  return "[" + io::format_setting_number(minimum) + ", " + io::format_setting_number(maximum) + "]";
}

}  // namespace

CommandLine::CommandLine(int argc, const char* const* argv, std::string usage, OnFailure on_failure)
    : program_(argc > 0 ? argv[0] : "covoxslam"),
      usage_(std::move(usage)),
      on_failure_(on_failure) {
  for (int i = 1; i < argc; ++i) arguments_.emplace_back(argv[i]);
  for (const std::string& argument : arguments_) {
    if (argument == "--help" || argument == "-h") {
      std::cout << usage_ << std::endl;
      std::exit(0);
    }
  }
}

size_t CommandLine::find_once(const std::string& name) {
  size_t found = std::string::npos;
  for (size_t i = 0; i < arguments_.size(); ++i) {
    if (arguments_[i] != name) continue;
    if (found != std::string::npos) fail(name + " is given twice: give each option once");
    found = i;
  }
  return found;
}

const std::string* CommandLine::find_value(const std::string& name) {
  const size_t i = find_once(name);
  if (i == std::string::npos) return nullptr;
  if (i + 1 >= arguments_.size()) fail(name + " needs a value");
  const std::string& value = arguments_[i + 1];
  if (value.size() > 2 && value.compare(0, 2, "--") == 0)
    fail(name + " needs a value, got the option '" + value + "'");
  consumed_.insert(i);
  consumed_.insert(i + 1);
  return &value;
}

std::string CommandLine::text(const std::string& name, const std::string& fallback) {
  const std::string* value = find_value(name);
  return value ? *value : fallback;
}

int64_t CommandLine::integer(const std::string& name, int64_t fallback, int64_t minimum,
                             int64_t maximum) {
  const std::string* value = find_value(name);
  if (!value) return fallback;
  int64_t parsed = 0;
  const std::string problem = io::parse_integer_value(*value, &parsed);
  if (!problem.empty() || parsed < minimum || parsed > maximum) {
    fail(name + " takes an integer in [" + std::to_string(minimum) + ", " +
         std::to_string(maximum) + "], got '" + *value + "'");
  }
  return parsed;
}

int64_t CommandLine::positive_integer(const std::string& name, int64_t fallback, int64_t maximum) {
  return integer(name, fallback, 1, maximum);
}

double CommandLine::number(const std::string& name, double fallback, double minimum,
                           double maximum) {
  const std::string* value = find_value(name);
  if (!value) return fallback;
  double parsed = 0.0;
  const std::string problem = io::parse_number_value(*value, &parsed);
  if (!problem.empty()) fail(name + ": " + problem);
  if (parsed < minimum || parsed > maximum)
    fail(name + " takes a number in " + range_text(minimum, maximum) + ", got '" + *value + "'");
  return parsed;
}

std::vector<double> CommandLine::numbers(const std::string& name,
                                         const std::vector<double>& fallback, double minimum,
                                         double maximum) {
  const std::string* value = find_value(name);
  if (!value) return fallback;
  std::vector<double> parsed;
  size_t start = 0;
  for (;;) {
    const size_t comma = value->find(',', start);
    const std::string item =
        value->substr(start, comma == std::string::npos ? comma : comma - start);
    double number = 0.0;
    const std::string problem = io::parse_number_value(item, &number);
    if (!problem.empty()) fail(name + " takes comma-separated numbers: " + problem);
    if (number < minimum || number > maximum)
      fail(name + " takes numbers in " + range_text(minimum, maximum) + ", got '" + item + "'");
    parsed.push_back(number);
    if (comma == std::string::npos) return parsed;
    start = comma + 1;
  }
}

std::string CommandLine::output_file(const std::string& name, const std::string& fallback) {
  const std::string path = text(name, fallback);
  if (path.empty()) return path;
  try {
    io::probe_output_path(path);
  } catch (const Error& error) {
    fail(name + " " + path + ": " + error.what());
  }
  return path;
}

std::string CommandLine::output_folder(const std::string& name, const std::string& fallback) {
  const std::string path = text(name, fallback);
  std::error_code error;
  std::filesystem::create_directories(path, error);
  if (error) fail(name + " " + path + ": cannot create the folder: " + error.message());
  try {
    io::probe_output_path(path + "/.probe");
  } catch (const Error& problem) {
    fail(name + " " + path + ": " + problem.what());
  }
  return path;
}

bool CommandLine::flag(const std::string& name) {
  const size_t i = find_once(name);
  if (i == std::string::npos) return false;
  consumed_.insert(i);
  return true;
}

void CommandLine::finish() const {
  for (size_t i = 0; i < arguments_.size(); ++i) {
    if (!consumed_.count(i)) fail("unknown option '" + arguments_[i] + "'");
  }
}

void CommandLine::fail(const std::string& problem) const {
  if (on_failure_ == OnFailure::kThrow) throw Error(problem);
  std::cerr << program_ << ": " << problem << "\n" << usage_ << std::endl;
  std::exit(2);
}

std::vector<Device> benchmark_devices(const std::string& request) {
  if (request != "all") return {select_device(parse_device_request(request))};
  std::vector<Device> devices = available_devices();
  // GPU first: its figures are the headline, and the CPU runs are the slow part.
  std::stable_partition(devices.begin(), devices.end(),
                        [](Device d) { return d == Device::kCuda; });
  return devices;
}

std::string describe_devices(const std::vector<Device>& devices) {
  std::string names;
  for (Device d : devices) names += (names.empty() ? "" : "; ") + describe_device(d);
  return names;
}

}  // namespace tools
}  // namespace covox

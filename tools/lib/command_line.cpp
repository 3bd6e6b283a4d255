#include "command_line.h"

#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <sstream>

namespace covox {
namespace tools {

CommandLine::CommandLine(int argc, const char* const* argv, std::string usage)
    : program_(argc > 0 ? argv[0] : "covoxslam"), usage_(std::move(usage)) {
  for (int i = 1; i < argc; ++i) arguments_.emplace_back(argv[i]);
  for (const std::string& argument : arguments_) {
    if (argument == "--help" || argument == "-h") {
      std::cout << usage_ << std::endl;
      std::exit(0);
    }
  }
}

const std::string* CommandLine::find_value(const std::string& name) {
  for (size_t i = 0; i < arguments_.size(); ++i) {
    if (arguments_[i] != name) continue;
    if (i + 1 >= arguments_.size()) fail(name + " needs a value");
    consumed_.insert(i);
    consumed_.insert(i + 1);
    return &arguments_[i + 1];
  }
  return nullptr;
}

std::string CommandLine::text(const std::string& name, const std::string& fallback) {
  const std::string* value = find_value(name);
  return value ? *value : fallback;
}

int64_t CommandLine::integer(const std::string& name, int64_t fallback) {
  const std::string* value = find_value(name);
  if (!value) return fallback;
  char* end = nullptr;
  const long long parsed = std::strtoll(value->c_str(), &end, 10);
  if (value->empty() || *end != '\0') fail(name + " expects an integer, got '" + *value + "'");
  return parsed;
}

int64_t CommandLine::positive_integer(const std::string& name, int64_t fallback) {
  const int64_t value = integer(name, fallback);
  if (value <= 0) fail(name + " must be positive");
  return value;
}

double CommandLine::number(const std::string& name, double fallback) {
  const std::string* value = find_value(name);
  if (!value) return fallback;
  char* end = nullptr;
  const double parsed = std::strtod(value->c_str(), &end);
  if (value->empty() || *end != '\0') fail(name + " expects a number, got '" + *value + "'");
  return parsed;
}

std::vector<double> CommandLine::numbers(const std::string& name,
                                         const std::vector<double>& fallback) {
  const std::string* value = find_value(name);
  if (!value) return fallback;
  std::vector<double> parsed;
  std::stringstream list(*value);
  for (std::string item; std::getline(list, item, ',');) {
    char* end = nullptr;
    parsed.push_back(std::strtod(item.c_str(), &end));
    if (item.empty() || *end != '\0')
      fail(name + " expects comma-separated numbers, got '" + *value + "'");
  }
  return parsed;
}

bool CommandLine::flag(const std::string& name) {
  for (size_t i = 0; i < arguments_.size(); ++i) {
    if (arguments_[i] == name) {
      consumed_.insert(i);
      return true;
    }
  }
  return false;
}

void CommandLine::finish() const {
  for (size_t i = 0; i < arguments_.size(); ++i) {
    if (!consumed_.count(i)) fail("unknown option '" + arguments_[i] + "'");
  }
}

void CommandLine::fail(const std::string& problem) const {
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

#pragma once
// Reading a SlamConfig from named parameters (the ROS parameter server, a test's table), with
// every value checked at start-up and a bad one reported by its parameter name.
//
// The names are those of config/covoxslam.yaml and docs/ros.md. The source is an interface so
// that the ROS layer (ros::NodeHandle) and the main test suite (a plain map) share this code.
// A parameter that is not set keeps the SlamConfig default; one set with the wrong type or an
// invalid value throws covox::Error naming it. After the per-parameter checks the library's
// own validate(SlamConfig) runs, so relations between parameters (truncation >= voxel size,
// max ray > min ray) are checked where the library defines them.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

class ParameterSource {
 public:
  virtual ~ParameterSource() = default;
  // Each returns false when `name` is not set. When it is set but cannot be read as the asked
  // type, implementations throw covox::Error naming it.
  virtual bool get_number(const std::string& name, double* value) const = 0;
  virtual bool get_integer(const std::string& name, int64_t* value) const = 0;
  virtual bool get_bool(const std::string& name, bool* value) const = 0;
  virtual bool get_text(const std::string& name, std::string* value) const = 0;
};

// A ParameterSource over a table of texts ("0.2", "true", "time"), for tests and tools.
class TextParameterSource : public ParameterSource {
 public:
  explicit TextParameterSource(std::map<std::string, std::string> values)
      : values_(std::move(values)) {}
  bool get_number(const std::string& name, double* value) const override;
  bool get_integer(const std::string& name, int64_t* value) const override;
  bool get_bool(const std::string& name, bool* value) const override;
  bool get_text(const std::string& name, std::string* value) const override;

 private:
  std::map<std::string, std::string> values_;
};

// Reads every SLAM parameter that `source` sets into `config` (defaults stay for the others) and
// validates the result. Throws covox::Error naming the first bad parameter.
void read_slam_config(const ParameterSource& source, SlamConfig* config);

// The names read_slam_config() reads, so a caller can warn about unknown (misspelt) ones.
const std::vector<std::string>& slam_parameter_names();

}  // namespace pipeline
}  // namespace covox

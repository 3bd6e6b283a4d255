#pragma once
// Reading a SlamConfig from named parameters (a configuration file, the ROS parameter server, a
// test's table), with every value checked at start-up and a bad one reported by its name
// (docs/parameters.md lists every one with its unit and default). The source is an interface so
// that configuration files (slam_config_files.h), the ROS layer and the tests share this code. A
// parameter that is not set keeps the SlamConfig default; one set with the wrong type or an
// invalid value throws covox::Error naming it. Then validate(SlamConfig) checks the relations
// between parameters (truncation >= voxel size, max ray > min ray) where the library defines them.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

// Names are the configuration files' paths of nested keys joined by '.', e.g.
// "registration.gate.max_residual_vox" for
//   registration:
//     gate:
//       max_residual_vox: 3.0
// (the ROS parameter server holds the same as ~registration/gate/max_residual_vox).
class ParameterSource {
 public:
  virtual ~ParameterSource() = default;
  // Each returns false when `name` is not set. When it is set but cannot be read as the asked
  // type, implementations throw covox::Error naming it.
  virtual bool get_number(const std::string& name, double* value) const = 0;
  virtual bool get_integer(const std::string& name, int64_t* value) const = 0;
  virtual bool get_bool(const std::string& name, bool* value) const = 0;
  virtual bool get_text(const std::string& name, std::string* value) const = 0;
  // Where `name` was set (e.g. "config/arche.yaml:12"), to prefix an error about its value;
  // empty when the name alone says it.
  virtual std::string location(const std::string& name) const {
    (void)name;
    return std::string();
  }
};

// A ParameterSource over a table of texts ("0.2", "true", "time"), for files, tests and tools;
// `locations` optionally names where each value was written.
class TextParameterSource : public ParameterSource {
 public:
  explicit TextParameterSource(std::map<std::string, std::string> values,
                               std::map<std::string, std::string> locations = {})
      : values_(std::move(values)), locations_(std::move(locations)) {}
  bool get_number(const std::string& name, double* value) const override;
  bool get_integer(const std::string& name, int64_t* value) const override;
  bool get_bool(const std::string& name, bool* value) const override;
  bool get_text(const std::string& name, std::string* value) const override;
  std::string location(const std::string& name) const override;

 private:
  std::map<std::string, std::string> values_;
  std::map<std::string, std::string> locations_;
};

// Reads every SLAM parameter that `source` sets into `config` (defaults stay for the others) and
// validates the result. Throws covox::Error naming the first bad parameter.
void read_slam_config(const ParameterSource& source, SlamConfig* config);

// The names read_slam_config() reads, so a caller can warn about unknown (misspelt) ones.
const std::vector<std::string>& slam_parameter_names();

}  // namespace pipeline
}  // namespace covox

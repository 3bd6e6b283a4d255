#pragma once
// The configuration files in config/: YAML (the subset of io/yaml_subset.h) with the parameters
// of pipeline/slam_parameters.h as nested sections, plus a `ros` section with the nodelet's own
// settings (frames, waiting, publishing) that the library lists but does not read. A file sets
// only what differs from the library defaults; docs/parameters.md lists every parameter.
//
// The named files are the presets, each the facts of one sensor (resolution, range, weighting,
// submap length, frames) over the library's one configuration: arche (the OS1-64 of the ARCHE and
// simulated flights, what `make demo` runs), rgbd, lidar_keyframes, covoxslam (the nodelet's
// generic default) and jetson (memory budgets). The offline runner, the benchmarks, the nodelet's
// launch files and the tests all read these files, so a preset exists once.
#include <cstddef>
#include <map>
#include <string>
#include <vector>

#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

// What a configuration file held.
struct SlamConfigFileUse {
  size_t applied = 0;                  // SLAM parameters it set
  std::vector<std::string> node_keys;  // keys of its `ros` section ("ros.odom_frame", ...)
};

// The values of configuration files, read as the offline runner and the node both read them:
// every entry as its text (SLAM parameters by their dotted names, the nodelet's as "ros.<name>"),
// with where it was written. A later file's value replaces an earlier file's.
struct ConfigFileValues {
  std::map<std::string, std::string> values;
  std::map<std::string, std::string> locations;  // "file:line"
};
// Reads the files in order; an empty path is skipped. Throws covox::Error ("file:line: problem")
// for a line outside the YAML subset and for an unknown SLAM parameter (a key outside the `ros`
// section that slam_parameter_names() does not list).
ConfigFileValues read_config_files(const std::vector<std::string>& paths);

// Applies the configuration file at `path` over `*config`: each parameter it sets replaces the
// value there, the others stay. Throws covox::Error, with the file and line where there is one,
// for a line outside the YAML subset, an unknown key or a bad value; `*config` is unchanged then.
SlamConfigFileUse load_slam_config(const std::string& path, SlamConfig* config);

// The folder of the configuration files: $COVOX_CONFIG_DIR when it is set, else the source
// tree's config/ when it exists, else the installed share/covoxslam/config.
std::string config_directory();
// The presets: the names of the *.yaml files in config_directory(), sorted.
std::vector<std::string> preset_names();
// The file of preset `name`; throws covox::Error naming the folder and listing the presets when
// there is none.
std::string preset_path(const std::string& name);
// The library defaults with preset `name` applied (device: the CPU, as SlamConfig's default).
SlamConfig load_preset(const std::string& name);

}  // namespace pipeline
}  // namespace covox

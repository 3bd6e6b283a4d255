#include "covoxslam/pipeline/slam_config_files.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <map>

#include "covoxslam/core/error.h"
#include "covoxslam/io/yaml_subset.h"
#include "covoxslam/pipeline/slam_parameters.h"

// Set by CMake for this file: the source tree's and the installed configuration folders.
#ifndef COVOX_CONFIG_SOURCE_DIR
#define COVOX_CONFIG_SOURCE_DIR ""
#endif
#ifndef COVOX_CONFIG_INSTALL_DIR
#define COVOX_CONFIG_INSTALL_DIR ""
#endif

namespace covox {
namespace pipeline {

namespace {

namespace fs = std::filesystem;

// The section of a file that belongs to the nodelet.
const char kNodeSection[] = "ros.";

bool is_slam_parameter(const std::string& key) {
  const std::vector<std::string>& names = slam_parameter_names();
  return std::find(names.begin(), names.end(), key) != names.end();
}

bool is_node_key(const std::string& key) {
  return key.compare(0, sizeof(kNodeSection) - 1, kNodeSection) == 0;
}

// Parameters that became voxel counts: a file written for an earlier release names the new key
// and how to convert, instead of only "unknown".
std::string renamed_parameter_hint(const std::string& key) {
  static const std::map<std::string, std::string> kInVoxels = {
      {"registration.information.min_sigma_m", "registration.information.min_sigma_vox"},
      {"registration.gate.max_residual_m", "registration.gate.max_residual_vox"},
      {"pose_graph.odometry_translation_sigma_m", "pose_graph.odometry_translation_sigma_vox"}};
  const auto renamed = kInVoxels.find(key);
  if (renamed == kInVoxels.end()) return "";
  return ": renamed to '" + renamed->second +
         "', in voxels (the value in metres divided by map.voxel_size_m)";
}

}  // namespace

ConfigFileValues read_config_files(const std::vector<std::string>& paths) {
  ConfigFileValues read;
  for (const std::string& path : paths) {
    if (path.empty()) continue;
    const io::YamlDocument document = io::read_yaml_subset(path);
    for (const io::YamlEntry& entry : document.entries) {
      if (!is_node_key(entry.key) && !is_slam_parameter(entry.key)) {
        const std::string hint = renamed_parameter_hint(entry.key);
        if (!hint.empty())
          throw Error(document.where(entry) + ": parameter '" + entry.key + "'" + hint);
        throw Error(document.where(entry) + ": unknown parameter '" + entry.key +
                    "' (docs/parameters.md lists them; the nodelet's own go in the `ros` section)");
      }
      read.values[entry.key] = entry.value;
      read.locations[entry.key] = document.where(entry);
    }
  }
  return read;
}

SlamConfigFileUse load_slam_config(const std::string& path, SlamConfig* config) {
  ConfigFileValues read = read_config_files({path});
  std::map<std::string, std::string> values, locations;
  SlamConfigFileUse use;
  for (const auto& [key, value] : read.values) {
    if (is_node_key(key)) {
      use.node_keys.push_back(key);
    } else {
      values[key] = value;
      locations[key] = read.locations[key];
    }
  }
  use.applied = values.size();
  SlamConfig updated = *config;
  read_slam_config(TextParameterSource(std::move(values), std::move(locations)), &updated);
  *config = updated;
  return use;
}

std::string config_directory() {
  const char* environment = std::getenv("COVOX_CONFIG_DIR");
  if (environment && *environment) return environment;
  const std::string source = COVOX_CONFIG_SOURCE_DIR;
  std::error_code error;
  if (!source.empty() && fs::is_directory(source, error)) return source;
  return COVOX_CONFIG_INSTALL_DIR;
}

std::vector<std::string> preset_names() {
  std::vector<std::string> names;
  std::error_code error;
  const std::string folder = config_directory();
  if (folder.empty() || !fs::is_directory(folder, error)) return names;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder, error)) {
    if (entry.is_regular_file(error) && entry.path().extension() == ".yaml") {
      names.push_back(entry.path().stem().string());
    }
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::string preset_path(const std::string& name) {
  const std::vector<std::string> names = preset_names();
  if (std::find(names.begin(), names.end(), name) != names.end()) {
    return (fs::path(config_directory()) / (name + ".yaml")).string();
  }
  std::string list;
  for (const std::string& known : names) list += (list.empty() ? "" : ", ") + known;
  throw Error("unknown preset '" + name + "': the presets in '" + config_directory() +
              "' (set COVOX_CONFIG_DIR for another folder) are " +
              (list.empty() ? std::string("none") : list));
}

SlamConfig load_preset(const std::string& name) {
  SlamConfig config;
  load_slam_config(preset_path(name), &config);
  return config;
}

}  // namespace pipeline
}  // namespace covox

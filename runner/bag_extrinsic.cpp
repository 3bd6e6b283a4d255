#include "runner/bag_extrinsic.h"

#include "covoxslam/core/error.h"
#include "covoxslam/io/transform_numbers.h"
#include "covoxslam/io/yaml_subset.h"

namespace covox {
namespace tools {
namespace {

// The extrinsic settings of the configuration files; empty texts: not set.
struct ConfigExtrinsic {
  std::string base_frame;
  bool use_tf = true;
  std::string T_base_sensor_text, T_base_sensor_where, use_tf_where;
};

ConfigExtrinsic read_config_extrinsic(const std::vector<std::string>& config_paths) {
  ConfigExtrinsic config;
  for (const std::string& path : config_paths) {
    const io::YamlDocument document = io::read_yaml_subset(path);
    for (const io::YamlEntry& entry : document.entries) {
      if (entry.key == "ros.base_frame") {
        config.base_frame = entry.value;
      } else if (entry.key == "ros.T_base_sensor") {
        config.T_base_sensor_text = entry.value;
        config.T_base_sensor_where = document.where(entry);
      } else if (entry.key == "ros.use_tf_for_extrinsic") {
        if (entry.value != "true" && entry.value != "false") {
          throw Error(document.where(entry) + ": parameter 'ros.use_tf_for_extrinsic': expected " +
                      "true or false, got '" + entry.value + "'");
        }
        config.use_tf = entry.value == "true";
        config.use_tf_where = document.where(entry);
      }
    }
  }
  return config;
}

// tf2 frame ids have no leading slash (the nodelet strips it too).
std::string frame_id(std::string frame) {
  if (!frame.empty() && frame.front() == '/') frame.erase(0, 1);
  return frame;
}

}  // namespace

void resolve_bag_extrinsic(const std::vector<std::string>& config_paths,
                           const std::string& base_frame_option,
                           const std::string& extrinsic_option, BagScanOptions* options) {
  const ConfigExtrinsic config = read_config_extrinsic(config_paths);
  if (!config.base_frame.empty()) options->base_frame = frame_id(config.base_frame);
  if (!base_frame_option.empty()) options->base_frame = frame_id(base_frame_option);
  if (options->base_frame.empty())
    throw Error("the base frame (--base-frame, ros.base_frame) is empty");
  if (!extrinsic_option.empty()) {
    options->T_base_sensor = io::transform_from_text(extrinsic_option, "--extrinsic");
    options->extrinsic_origin = "--extrinsic";
  } else if (!config.use_tf) {
    // The nodelet's default T_base_sensor is the identity.
    options->T_base_sensor = Eigen::Isometry3d::Identity();
    options->extrinsic_origin = "ros.T_base_sensor (default identity; " + config.use_tf_where +
                                " sets use_tf_for_extrinsic: false)";
    if (!config.T_base_sensor_text.empty()) {
      const std::string what = config.T_base_sensor_where + ": parameter 'ros.T_base_sensor'";
      options->T_base_sensor = io::transform_from_text(config.T_base_sensor_text, what);
      options->extrinsic_origin = "ros.T_base_sensor of " + config.T_base_sensor_where;
    }
  }
}

}  // namespace tools
}  // namespace covox

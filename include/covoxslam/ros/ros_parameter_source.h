#pragma once
// The node's parameters as a pipeline::ParameterSource, read the way the offline runner reads a
// configuration file: the files named by ~config_file and ~extra_config_file are read by the
// library's reader (pipeline::read_config_files), and a parameter set on the server replaces a
// file's value. Both go through the same text parsing (io/setting_values.h; a server value is
// turned into its text first, a double in its shortest exact form), so a file works in both or
// fails in both. Dotted names are nested parameters ("registration.gate.max_residual_vox" is
// ~registration/gate/max_residual_vox); a section's source ("ros") reads ~ros/<name> and the
// files' "ros.<name>" entries.
#include <string>
#include <vector>

#include <ros/node_handle.h>

#include "covoxslam/pipeline/slam_config_files.h"
#include "covoxslam/pipeline/slam_parameters.h"

namespace covox {
namespace ros_layer {

class RosParameterSource : public pipeline::ParameterSource {
 public:
  // Reads the configuration files named by `private_node`'s config_file and extra_config_file
  // (throws covox::Error naming a bad file or line). `section`: "" for the SLAM parameters,
  // "ros" for the node options.
  explicit RosParameterSource(const ros::NodeHandle& private_node, const std::string& section = "");
  bool get_number(const std::string& name, double* value) const override;
  bool get_integer(const std::string& name, int64_t* value) const override;
  bool get_bool(const std::string& name, bool* value) const override;
  bool get_text(const std::string& name, std::string* value) const override;
  // A list of numbers: a server list, or a file's flow list "[1, 2, 3]".
  bool get_number_list(const std::string& name, std::vector<double>* values) const;
  std::string location(const std::string& name) const override;

  // The file entries of this source's section that `known` does not list (misspelt keys).
  std::vector<std::string> unknown_file_keys(const std::vector<std::string>& known) const;

  // "registration.gate.max_residual_vox" -> "registration/gate/max_residual_vox".
  static std::string ros_name(const std::string& name);
  // The private parameters naming the configuration files.
  static const std::vector<std::string>& file_parameter_names();

 private:
  // The text of `name`: the server's value turned into text, else the files'; `label` names
  // where it was set for messages. False when unset.
  bool text_of(const std::string& name, std::string* text, std::string* label) const;
  // `name` for a value message, with `where` it was set unless the caller adds that.
  std::string labelled(const std::string& name, const std::string& where) const;

  ros::NodeHandle node_;  // the section's node handle
  std::string prefix_;    // "" or "ros."
  pipeline::ConfigFileValues files_;
};

}  // namespace ros_layer
}  // namespace covox

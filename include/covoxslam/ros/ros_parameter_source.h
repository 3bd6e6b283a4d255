#pragma once
// The ROS parameter server as a pipeline::ParameterSource: a parameter set with the wrong type
// (a text where a number belongs) is an error naming it, not a silently kept default. The
// library's dotted names are nested parameters: "registration.gate.max_residual_m" is
// ~registration/gate/max_residual_m, as `rosparam load` of a configuration file sets it.
#include <string>

#include <ros/node_handle.h>

#include "covoxslam/pipeline/slam_parameters.h"

namespace covox {
namespace ros_layer {

class RosParameterSource : public pipeline::ParameterSource {
 public:
  explicit RosParameterSource(const ros::NodeHandle& node) : node_(node) {}
  bool get_number(const std::string& name, double* value) const override;
  bool get_integer(const std::string& name, int64_t* value) const override;
  bool get_bool(const std::string& name, bool* value) const override;
  bool get_text(const std::string& name, std::string* value) const override;
  std::string location(const std::string& name) const override;

  // "registration.gate.max_residual_m" -> "registration/gate/max_residual_m".
  static std::string ros_name(const std::string& name);

 private:
  ros::NodeHandle node_;
};

}  // namespace ros_layer
}  // namespace covox

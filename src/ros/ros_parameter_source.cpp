#include "covoxslam/ros/ros_parameter_source.h"

#include "covoxslam/core/error.h"

namespace covox {
namespace ros_layer {

namespace {
[[noreturn]] void wrong_type(const ros::NodeHandle& node, const std::string& name,
                             const char* expected) {
  throw Error("parameter '" + node.resolveName(name) + "': expected " + expected);
}
}  // namespace

bool RosParameterSource::get_number(const std::string& name, double* value) const {
  if (!node_.hasParam(name)) return false;
  // getParam(double) also accepts integers ("5" for 5.0).
  if (!node_.getParam(name, *value)) wrong_type(node_, name, "a number");
  return true;
}

bool RosParameterSource::get_integer(const std::string& name, int64_t* value) const {
  if (!node_.hasParam(name)) return false;
  int parsed = 0;
  if (!node_.getParam(name, parsed)) wrong_type(node_, name, "an integer");
  *value = parsed;
  return true;
}

bool RosParameterSource::get_bool(const std::string& name, bool* value) const {
  if (!node_.hasParam(name)) return false;
  if (!node_.getParam(name, *value)) wrong_type(node_, name, "true or false");
  return true;
}

bool RosParameterSource::get_text(const std::string& name, std::string* value) const {
  if (!node_.hasParam(name)) return false;
  if (!node_.getParam(name, *value)) wrong_type(node_, name, "a text");
  return true;
}

}  // namespace ros_layer
}  // namespace covox

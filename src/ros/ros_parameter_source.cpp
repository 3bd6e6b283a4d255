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

std::string RosParameterSource::ros_name(const std::string& name) {
  std::string nested = name;
  for (char& c : nested) {
    if (c == '.') c = '/';
  }
  return nested;
}

std::string RosParameterSource::location(const std::string& name) const {
  return node_.resolveName(ros_name(name));
}

bool RosParameterSource::get_number(const std::string& dotted, double* value) const {
  const std::string name = ros_name(dotted);
  if (!node_.hasParam(name)) return false;
  // getParam(double) also accepts integers ("5" for 5.0).
  if (!node_.getParam(name, *value)) wrong_type(node_, name, "a number");
  return true;
}

bool RosParameterSource::get_integer(const std::string& dotted, int64_t* value) const {
  const std::string name = ros_name(dotted);
  if (!node_.hasParam(name)) return false;
  int parsed = 0;
  if (!node_.getParam(name, parsed)) wrong_type(node_, name, "an integer");
  *value = parsed;
  return true;
}

bool RosParameterSource::get_bool(const std::string& dotted, bool* value) const {
  const std::string name = ros_name(dotted);
  if (!node_.hasParam(name)) return false;
  if (!node_.getParam(name, *value)) wrong_type(node_, name, "true or false");
  return true;
}

bool RosParameterSource::get_text(const std::string& dotted, std::string* value) const {
  const std::string name = ros_name(dotted);
  if (!node_.hasParam(name)) return false;
  if (!node_.getParam(name, *value)) wrong_type(node_, name, "a text");
  return true;
}

}  // namespace ros_layer
}  // namespace covox

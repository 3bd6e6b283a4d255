#include "covoxslam/ros/ros_parameter_source.h"

#include <algorithm>
#include <map>

#include "covoxslam/core/error.h"
#include "covoxslam/io/setting_values.h"

namespace covox {
namespace ros_layer {

namespace {

[[noreturn]] void wrong_type(const ros::NodeHandle& node, const std::string& name,
                             const char* found) {
  throw Error("parameter '" + node.resolveName(name) + "': expected a single value, got " + found);
}

// A server value as the text a configuration file would hold for it.
std::string server_text(const ros::NodeHandle& node, const std::string& name,
                        XmlRpc::XmlRpcValue& value) {
  switch (value.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean:
      return static_cast<bool>(value) ? "true" : "false";
    case XmlRpc::XmlRpcValue::TypeInt:
      return std::to_string(static_cast<int>(value));
    case XmlRpc::XmlRpcValue::TypeDouble:
      return io::format_setting_number(static_cast<double>(value));
    case XmlRpc::XmlRpcValue::TypeString:
      return static_cast<std::string>(value);
    case XmlRpc::XmlRpcValue::TypeArray:
      wrong_type(node, name, "a list");
    case XmlRpc::XmlRpcValue::TypeStruct:
      wrong_type(node, name, "a mapping");
    default:
      wrong_type(node, name, "a value of another type (date or binary)");
  }
}

// "[1, 2.5, -3]" -> its items' texts; false when `text` is no flow list.
bool flow_list_items(const std::string& text, std::vector<std::string>* items) {
  if (text.size() < 2 || text.front() != '[' || text.back() != ']') return false;
  const std::string inner = text.substr(1, text.size() - 2);
  size_t start = 0;
  for (;;) {
    const size_t comma = inner.find(',', start);
    std::string item = inner.substr(start, comma == std::string::npos ? comma : comma - start);
    const size_t first = item.find_first_not_of(' ');
    const size_t last = item.find_last_not_of(' ');
    items->push_back(first == std::string::npos ? "" : item.substr(first, last - first + 1));
    if (comma == std::string::npos) return true;
    start = comma + 1;
  }
}

// The library's text parsing of one value, with `label` naming it in messages.
pipeline::TextParameterSource single_value(const std::string& label, const std::string& text) {
  return pipeline::TextParameterSource(std::map<std::string, std::string>{{label, text}});
}

}  // namespace

RosParameterSource::RosParameterSource(const ros::NodeHandle& private_node,
                                       const std::string& section)
    : node_(section.empty() ? private_node : ros::NodeHandle(private_node, section)),
      prefix_(section.empty() ? "" : section + ".") {
  std::vector<std::string> paths;
  for (const std::string& parameter : file_parameter_names()) {
    std::string path;
    if (private_node.hasParam(parameter) && !private_node.getParam(parameter, path))
      throw Error("parameter '" + private_node.resolveName(parameter) + "': expected a file path");
    paths.push_back(path);
  }
  files_ = pipeline::read_config_files(paths);
}

const std::vector<std::string>& RosParameterSource::file_parameter_names() {
  static const std::vector<std::string> names = {"config_file", "extra_config_file"};
  return names;
}

std::string RosParameterSource::ros_name(const std::string& name) {
  std::string nested = name;
  std::replace(nested.begin(), nested.end(), '.', '/');
  return nested;
}

std::string RosParameterSource::location(const std::string& name) const {
  const std::string server = ros_name(name);
  if (node_.hasParam(server)) return node_.resolveName(server);
  const auto it = files_.locations.find(prefix_ + name);
  return it == files_.locations.end() ? node_.resolveName(server) : it->second;
}

std::string RosParameterSource::labelled(const std::string& name, const std::string& where) const {
  // The SLAM parameters' messages get the location from read_slam_config (as run_slam's do); the
  // node options' readers name the parameter only, so their label carries it.
  return prefix_.empty() ? name : prefix_ + name + " in " + where;
}

bool RosParameterSource::text_of(const std::string& name, std::string* text,
                                 std::string* label) const {
  const std::string server = ros_name(name);
  XmlRpc::XmlRpcValue value;
  if (node_.hasParam(server) && node_.getParam(server, value)) {
    *text = server_text(node_, server, value);
    *label = labelled(name, node_.resolveName(server));
    return true;
  }
  const auto it = files_.values.find(prefix_ + name);
  if (it == files_.values.end()) return false;
  *text = it->second;
  *label = labelled(name, files_.locations.at(it->first));
  return true;
}

bool RosParameterSource::get_number(const std::string& name, double* value) const {
  std::string text, label;
  return text_of(name, &text, &label) && single_value(label, text).get_number(label, value);
}

bool RosParameterSource::get_integer(const std::string& name, int64_t* value) const {
  std::string text, label;
  return text_of(name, &text, &label) && single_value(label, text).get_integer(label, value);
}

bool RosParameterSource::get_bool(const std::string& name, bool* value) const {
  std::string text, label;
  return text_of(name, &text, &label) && single_value(label, text).get_bool(label, value);
}

bool RosParameterSource::get_text(const std::string& name, std::string* value) const {
  std::string label;
  return text_of(name, value, &label);
}

bool RosParameterSource::get_number_list(const std::string& name,
                                         std::vector<double>* values) const {
  const std::string server = ros_name(name);
  std::vector<std::string> items;
  XmlRpc::XmlRpcValue list;
  if (node_.hasParam(server) && node_.getParam(server, list) &&
      list.getType() == XmlRpc::XmlRpcValue::TypeArray) {
    for (int i = 0; i < list.size(); ++i) items.push_back(server_text(node_, server, list[i]));
  } else {
    std::string text, label;
    if (!text_of(name, &text, &label)) return false;
    if (!flow_list_items(text, &items))
      throw Error("parameter '" + location(name) + "': expected a list [a, b, ...], got '" + text +
                  "'");
  }
  values->clear();
  for (const std::string& item : items) {
    double value = 0.0;
    const std::string problem = io::parse_number_value(item, &value);
    if (!problem.empty()) throw Error("parameter '" + location(name) + "': " + problem);
    values->push_back(value);
  }
  return true;
}

std::vector<std::string> RosParameterSource::unknown_file_keys(
    const std::vector<std::string>& known) const {
  std::vector<std::string> unknown;
  for (const auto& entry : files_.values) {
    if (entry.first.compare(0, prefix_.size(), prefix_) != 0) continue;
    const std::string name = entry.first.substr(prefix_.size());
    if (prefix_.empty() && name.compare(0, 4, "ros.") == 0) continue;
    if (std::find(known.begin(), known.end(), name) == known.end())
      unknown.push_back(files_.locations.at(entry.first) + ": " + entry.first);
  }
  return unknown;
}

}  // namespace ros_layer
}  // namespace covox

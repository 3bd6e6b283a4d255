#pragma once
// The flat YAML of config/*.yaml (`name: value  # comment`, one parameter a line, no nesting), so
// that the offline runner takes the same parameter files as the ROS nodelet.
#include <map>
#include <string>

namespace covox {
namespace tools {

// Name -> value text, comments and surrounding quotes removed. Throws covox::Error naming the file
// and line for a line that is not `name: value`, a nested block, or a name given twice.
std::map<std::string, std::string> read_flat_yaml(const std::string& path);

}  // namespace tools
}  // namespace covox

#include "flat_yaml.h"

#include <fstream>

#include "covoxslam/core/error.h"

namespace covox {
namespace tools {
namespace {

std::string trim(const std::string& text) {
  const size_t first = text.find_first_not_of(" \t\r");
  if (first == std::string::npos) return std::string();
  const size_t last = text.find_last_not_of(" \t\r");
  return text.substr(first, last - first + 1);
}

}  // namespace

std::map<std::string, std::string> read_flat_yaml(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw Error("cannot open parameter file '" + path + "'");
  std::map<std::string, std::string> values;
  std::string line;
  for (int number = 1; std::getline(file, line); ++number) {
    const std::string where = "'" + path + "' line " + std::to_string(number);
    // A '#' starts a comment unless it is inside quotes (frame names never hold one).
    bool quoted = false;
    for (size_t i = 0; i < line.size(); ++i) {
      if (line[i] == '"' || line[i] == '\'') quoted = !quoted;
      if (line[i] == '#' && !quoted) {
        line.resize(i);
        break;
      }
    }
    if (trim(line).empty() || trim(line) == "---") continue;
    if (line[0] == ' ' || line[0] == '\t' || trim(line)[0] == '-') {
      throw Error(where + ": nested YAML is not supported (one `name: value` a line)");
    }
    const size_t colon = line.find(':');
    if (colon == std::string::npos) throw Error(where + ": expected `name: value`");
    const std::string name = trim(line.substr(0, colon));
    std::string value = trim(line.substr(colon + 1));
    if (value.empty())
      throw Error(where + ": '" + name + "' has no value (nested YAML is not supported)");
    if (value.size() >= 2 && (value.front() == '"' || value.front() == '\'') &&
        value.back() == value.front()) {
      value = value.substr(1, value.size() - 2);
    }
    if (!values.emplace(name, value).second) throw Error(where + ": '" + name + "' is given twice");
  }
  return values;
}

}  // namespace tools
}  // namespace covox

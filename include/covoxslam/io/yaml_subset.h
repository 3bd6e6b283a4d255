#pragma once
// A reader for the subset of YAML that the configuration files in config/ use (the grammar:
// read_yaml_subset below), so that the library, which must not depend on a YAML library, loads
// them on any machine. Everything else is refused with "file:line: what" - block lists
// ("- item"), tabs in the indentation, flow mappings, anchors, tags, block scalars, a key given
// twice, a key without a value and without entries, an indentation that matches no open mapping.
// Values are kept as text; their meaning is the caller's (pipeline/slam_parameters.h reads them).
#include <string>
#include <vector>

namespace covox {
namespace io {

struct YamlEntry {
  std::string
      key;  // the path of mapping keys joined by '.', e.g. "registration.gate.worst_fraction"
  std::string value;  // the scalar's text without quotes; a flow list keeps its brackets
  int line = 0;       // 1-based line of the entry in its file
};

struct YamlDocument {
  std::string name;                // the file's path (or the name given to parse_yaml_subset)
  std::vector<YamlEntry> entries;  // every scalar entry in file order (sections have none)
  // "name:line", for error messages about an entry.
  std::string where(const YamlEntry& entry) const;
};

// The subset:
//   # a comment                      whole-line and trailing comments (a '#' after a space)
//   voxel_size_m: 0.2                `key: value`, one a line; keys are [A-Za-z0-9_-]+
//   registration:                    a key with no value opens a nested mapping: the lines
//     gate:                          below it, indented further (spaces only) and all by the
//       max_residual_vox: 3.0        same amount, are its entries
//   base_frame: "imu"                quoted scalars ('...' or "..." without escapes)
//   T_base_sensor: [0, 0, 0, 1]      a flow list of plain scalars, kept as its text
//
// Throws covox::Error ("file:line: problem") for anything outside the subset, and when the file
// cannot be read.
YamlDocument read_yaml_subset(const std::string& path);
// The same for text in memory; `name` stands for the file in messages.
YamlDocument parse_yaml_subset(const std::string& text, const std::string& name);

}  // namespace io
}  // namespace covox

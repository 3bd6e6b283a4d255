#pragma once
// Reads g2o SE(3) pose graphs (the standard benchmark format):
//   VERTEX_SE3:QUAT id x y z qx qy qz qw
//   EDGE_SE3:QUAT i j x y z qx qy qz qw  I11 I12 .. I16 I22 .. I66   (21 upper-triangular entries)
//   FIX id                                                           (optional gauge)
// Blank lines and '#' comments are skipped. Anything else is an error naming the file and line.
// The edge measurement is T_i^-1 T_j, the information is over (translation, rotation), as in the
// residual of pose_graph_models.h.
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/backend/pose_graph.h"

namespace covox {
namespace backend {

struct G2oGraph {
  Se3PoseGraph graph;               // fixed_vertex: the FIX'ed vertex, else the first one
  std::vector<int64_t> vertex_ids;  // the file's id of each pose index
};

// Throws covox::Error naming `path` (and the line) when the file cannot be read or is malformed:
// unknown tag, wrong field count, a token that is not a number, a duplicate vertex id, an edge
// naming an unknown vertex, an invalid information matrix.
G2oGraph read_g2o(const std::string& path);
// The same for text already in memory; `source_name` is used in error messages.
G2oGraph parse_g2o(const std::string& text, const std::string& source_name);

}  // namespace backend
}  // namespace covox

#pragma once
// Exact point-to-mesh distances, for comparing a reconstruction with a ground-truth mesh (the
// Replica accuracy test, the simulator's reconstruction evaluation). The mesh's triangles are
// listed in a uniform hash grid; a query visits shells of cells around its own until the nearest
// triangle found is closer than anything in an unvisited shell can be, so the answer is the
// exact distance, not an approximation, while touching only the cells near the query.
#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "covoxslam/map/mesh.h"

namespace covox {
namespace eval {

// The point of triangle (a, b, c) closest to p, by the Voronoi regions of its vertices, edges and
// face (Ericson, Real-Time Collision Detection, 5.1.5), in double precision. Degenerate triangles
// are fine: a == b == c (a point) gives a; collinear corners give a point of the segment or a.
Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c);

class MeshDistance {
 public:
  // Indexes `mesh` (copied: the index does not refer to it afterwards). A mesh without triangles
  // is taken as a point set, its vertices being the elements distances are measured to. The cell
  // size trades build cost and memory (small cells list a large triangle many times) against
  // query cost (large cells hold many triangles); about the usual query radius is a good choice.
  // Throws covox::Error when cell_size_m is not positive and finite.
  MeshDistance(const map::Mesh& mesh, double cell_size_m);

  // Distance from p to the nearest triangle (or vertex, for a point set) when that is at most
  // max_distance_m, exactly; +infinity when nothing lies that close. Throws covox::Error when
  // max_distance_m is negative or not finite, since the search must be bounded.
  double distance_m(const Eigen::Vector3d& p, double max_distance_m) const;

  size_t element_count() const { return triangles_.size(); }

 private:
  struct Triangle {
    Eigen::Vector3d a, b, c;
  };

  Eigen::Array3i cell_of(const Eigen::Vector3d& p) const;
  static int64_t key(int x, int y, int z);

  double cell_m_;
  std::vector<Triangle> triangles_;
  std::unordered_map<int64_t, std::vector<uint32_t>> cells_;
};

}  // namespace eval
}  // namespace covox

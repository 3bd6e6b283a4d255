#pragma once
// The independent reference of the demo-flight ESDF rostest (demo_flight_esdf_rostest.cpp): the
// simulator's ground-truth world as the triangles of its world.ply (simulate_flight writes every
// primitive there, outward-facing), with the exact distance from a point to the nearest triangle
// and a line-of-sight test. Nothing here uses covoxslam's own map, ESDF or mesh code.
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>

namespace covox_rostest {

struct WorldTriangle {
  Eigen::Vector3d a, b, c;
};

// The triangles of a binary little-endian PLY whose vertices start with float x, y, z and whose
// faces are `list uchar int vertex_indices` of three (what simulate_flight writes). Throws
// std::runtime_error naming the file and what is unexpected.
std::vector<WorldTriangle> read_world_ply(const std::string& path);

// The point of `triangle` nearest to `p` (exact: the face, an edge or a corner).
Eigen::Vector3d closest_point_on_triangle(const WorldTriangle& triangle, const Eigen::Vector3d& p);

// Unit normal along (b - a) x (c - a): outward for the world's counter-clockwise faces.
Eigen::Vector3d triangle_normal(const WorldTriangle& triangle);

// The triangles bucketed by the cubic cells (of `cell_m`) their bounding boxes overlap, so that
// the distance and line-of-sight questions look at the few triangles near a point or a segment.
class WorldMesh {
 public:
  WorldMesh(std::vector<WorldTriangle> triangles, double cell_m);

  const std::vector<WorldTriangle>& triangles() const { return triangles_; }
  // Distance from `p` to the nearest triangle when it is at most `max_m` (and that triangle's
  // nearest point and its normal in `nearest` and `normal`, if given); otherwise a value above
  // `max_m` (the cells further out are not searched).
  double distance(const Eigen::Vector3d& p, double max_m, Eigen::Vector3d* nearest = nullptr,
                  Eigen::Vector3d* normal = nullptr) const;
  // True when the segment from `from` to `to` crosses no triangle (ends excluded by `margin_m`).
  bool line_of_sight(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                     double margin_m = 1e-3) const;

 private:
  Eigen::Vector3i cell_of(const Eigen::Vector3d& p) const;
  static int64_t key(const Eigen::Vector3i& cell);
  // Indices of the triangles in the cells between `low` and `high`, each once.
  std::vector<uint32_t> triangles_in(const Eigen::Vector3d& low, const Eigen::Vector3d& high) const;

  std::vector<WorldTriangle> triangles_;
  double cell_m_;
  std::unordered_map<int64_t, std::vector<uint32_t>> cells_;
  mutable std::vector<uint32_t> visit_stamp_;  // per triangle: the query that last listed it
  mutable uint32_t query_ = 0;
};

}  // namespace covox_rostest

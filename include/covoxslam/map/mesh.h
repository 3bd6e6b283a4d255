#pragma once
// A triangle mesh on the host: what the mesh integrator produces and the PLY reader/writer and
// the ROS layer consume. It lives in `map` so that io does not depend on the integrators.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "covoxslam/core/vec3.h"

namespace covox::map {

// Triangle t uses vertices triangles[3t], [3t+1], [3t+2]; `colors` is empty or one per vertex.
struct Mesh {
  std::vector<Vec3f> vertices_m;
  std::vector<Rgb8> colors;
  std::vector<uint32_t> triangles;
  size_t triangle_count() const { return triangles.size() / 3; }
  bool empty() const { return triangles.empty(); }
};

}  // namespace covox::map

#pragma once
// The simulator's world: analytic primitives (planes, oriented boxes, vertical capped cylinders,
// spheres, triangles) with exact ray intersection, so simulated LiDAR ranges are exact up to the
// noise the sensor model adds, and a bounding volume hierarchy so that a scan of 65k rays against
// tens of thousands of primitives stays fast on a CPU. The same primitives tessellate into the
// ground-truth mesh that reconstructions are scored against (curved shapes are approximated
// there with `segments` facets; the ray intersection stays exact).
#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/integrators/mesh_integrator.h"

namespace covox {
namespace sim {

constexpr double kNoHit = std::numeric_limits<double>::infinity();

// Colours of the ground-truth mesh, by kind of object (for viewing only).
struct SurfaceColour {
  uint8_t r = 180, g = 180, b = 180;
};

struct Plane {
  Eigen::Vector3d point_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit
  double mesh_half_size_m = 50.0;                     // extent of its square in the mesh only
  SurfaceColour colour;
};

// rotation maps box axes to world axes: p_world = centre + rotation * p_box.
struct Box {
  Eigen::Vector3d centre_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_extent_m = Eigen::Vector3d::Ones();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  SurfaceColour colour;
};

// Axis along world z, closed by flat caps (poles, tree trunks).
struct Cylinder {
  Eigen::Vector3d base_centre_m = Eigen::Vector3d::Zero();
  double radius_m = 0.1;
  double height_m = 1.0;
  SurfaceColour colour;
};

struct Sphere {
  Eigen::Vector3d centre_m = Eigen::Vector3d::Zero();
  double radius_m = 1.0;
  SurfaceColour colour;
};

struct Triangle {
  Eigen::Vector3d a_m, b_m, c_m;
  SurfaceColour colour;
};

// Distance along a unit ray to each primitive's surface (the nearest crossing in front of the
// origin, outside or inside), or kNoHit.
double intersect(const Plane& plane, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction);
double intersect(const Box& box, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction);
double intersect(const Cylinder& cylinder, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction);
double intersect(const Sphere& sphere, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction);
double intersect(const Triangle& triangle, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction);

class World {
 public:
  void add(const Plane& plane) {
    planes_.push_back(plane);
    built_ = false;
  }
  void add(const Box& box) {
    boxes_.push_back(box);
    built_ = false;
  }
  void add(const Cylinder& cylinder) {
    cylinders_.push_back(cylinder);
    built_ = false;
  }
  void add(const Sphere& sphere) {
    spheres_.push_back(sphere);
    built_ = false;
  }
  void add(const Triangle& triangle) {
    triangles_.push_back(triangle);
    built_ = false;
  }

  // Builds the hierarchy; call after the last add() and before intersect() from several threads.
  void build();

  // Distance along the unit ray to the nearest surface, or kNoHit when nothing lies closer than
  // max_range_m. Throws covox::Error if primitives were added after the last build().
  double intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                   double max_range_m = kNoHit) const;

  // Every surface as triangles, outward-facing, coloured by object kind.
  map::Mesh to_mesh(int segments = 24) const;

  size_t primitive_count() const {
    return planes_.size() + boxes_.size() + cylinders_.size() + spheres_.size() + triangles_.size();
  }
  const std::vector<Box>& boxes() const { return boxes_; }
  const std::vector<Cylinder>& cylinders() const { return cylinders_; }
  const std::vector<Sphere>& spheres() const { return spheres_; }
  const std::vector<Triangle>& triangles() const { return triangles_; }

 private:
  enum class Kind : uint8_t { kBox, kCylinder, kSphere, kTriangle };
  struct Reference {
    Kind kind;
    uint32_t index;
  };
  struct Node {
    Eigen::Vector3d low, high;
    uint32_t first = 0;  // leaf: first reference; inner node: left child
    uint32_t count = 0;  // leaf: number of references; 0 for an inner node
    uint32_t right = 0;  // inner node: right child
  };
  void bounds_of(const Reference& reference, Eigen::Vector3d* low, Eigen::Vector3d* high) const;
  double intersect_reference(const Reference& reference, const Eigen::Vector3d& origin,
                             const Eigen::Vector3d& direction) const;
  uint32_t build_node(uint32_t first, uint32_t count, std::vector<Eigen::Vector3d>& centres,
                      std::vector<Eigen::Vector3d>& lows, std::vector<Eigen::Vector3d>& highs);

  std::vector<Plane> planes_;
  std::vector<Box> boxes_;
  std::vector<Cylinder> cylinders_;
  std::vector<Sphere> spheres_;
  std::vector<Triangle> triangles_;
  std::vector<Reference> references_;
  std::vector<Node> nodes_;
  bool built_ = false;
};

}  // namespace sim
}  // namespace covox

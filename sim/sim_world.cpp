#include "sim/sim_world.h"

#include <algorithm>
#include <cmath>

#include "covoxslam/core/error.h"

namespace covox {
namespace sim {
namespace {

// Hits closer than this are the ray's own start (a sensor touching a surface): ignored.
constexpr double kMinHitDistance_m = 1e-9;
constexpr double kPi = 3.14159265358979323846;
constexpr int kLeafSize = 4;

// Ray against an axis-aligned box given by its corners: the entry distance (clamped at 0), or
// kNoHit when the ray misses it or it lies entirely beyond `limit`.
double slab_entry(const Eigen::Vector3d& low, const Eigen::Vector3d& high,
                  const Eigen::Vector3d& origin, const Eigen::Vector3d& inverse_direction,
                  double limit) {
  double t_near = 0.0, t_far = limit;
  for (int axis = 0; axis < 3; ++axis) {
    double t1 = (low[axis] - origin[axis]) * inverse_direction[axis];
    double t2 = (high[axis] - origin[axis]) * inverse_direction[axis];
    if (t1 > t2) std::swap(t1, t2);
    // NaN (0 * inf, a ray in the slab's plane) must not shrink the interval: max/min with the
    // NaN second keeps the current bound.
    t_near = std::max(t_near, t1);
    t_far = std::min(t_far, t2);
    if (t_near > t_far) return kNoHit;
  }
  return t_near;
}

struct BuildItem {
  Eigen::Vector3d low, high, centre;
  uint32_t reference;
};

void append_triangle(map::Mesh* mesh, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                     const Eigen::Vector3d& c, const SurfaceColour& colour) {
  for (const Eigen::Vector3d* p : {&a, &b, &c}) {
    mesh->triangles.push_back(static_cast<uint32_t>(mesh->vertices_m.size()));
    mesh->vertices_m.emplace_back(static_cast<float>(p->x()), static_cast<float>(p->y()),
                                  static_cast<float>(p->z()));
    mesh->colors.push_back(Rgb8{colour.r, colour.g, colour.b});
  }
}

void append_quad(map::Mesh* mesh, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                 const Eigen::Vector3d& c, const Eigen::Vector3d& d, const SurfaceColour& colour) {
  append_triangle(mesh, a, b, c, colour);
  append_triangle(mesh, a, c, d, colour);
}

}  // namespace

double intersect(const Plane& plane, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction) {
  const double denominator = direction.dot(plane.normal);
  if (std::abs(denominator) < 1e-15) return kNoHit;
  const double t = (plane.point_m - origin).dot(plane.normal) / denominator;
  return t > kMinHitDistance_m ? t : kNoHit;
}

double intersect(const Box& box, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction) {
  // In the box frame the box is axis aligned: the slab test, with the exit distance when the
  // origin is inside.
  const Eigen::Vector3d o = box.rotation.transpose() * (origin - box.centre_m);
  const Eigen::Vector3d d = box.rotation.transpose() * direction;
  double t_near = -kNoHit, t_far = kNoHit;
  for (int axis = 0; axis < 3; ++axis) {
    const double h = box.half_extent_m[axis];
    if (std::abs(d[axis]) < 1e-15) {
      if (std::abs(o[axis]) > h) return kNoHit;
      continue;
    }
    double t1 = (-h - o[axis]) / d[axis], t2 = (h - o[axis]) / d[axis];
    if (t1 > t2) std::swap(t1, t2);
    t_near = std::max(t_near, t1);
    t_far = std::min(t_far, t2);
  }
  if (t_near > t_far || t_far <= kMinHitDistance_m) return kNoHit;
  return t_near > kMinHitDistance_m ? t_near : t_far;
}

double intersect(const Cylinder& cylinder, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction) {
  const double ox = origin.x() - cylinder.base_centre_m.x();
  const double oy = origin.y() - cylinder.base_centre_m.y();
  const double z_low = cylinder.base_centre_m.z(), z_high = z_low + cylinder.height_m;
  const double r2 = cylinder.radius_m * cylinder.radius_m;
  double best = kNoHit;
  // Mantle: |o_xy + t d_xy|^2 = r^2, kept where the hit height lies between the caps.
  const double a = direction.x() * direction.x() + direction.y() * direction.y();
  if (a > 1e-15) {
    const double b = ox * direction.x() + oy * direction.y();
    const double c = ox * ox + oy * oy - r2;
    const double discriminant = b * b - a * c;
    if (discriminant >= 0.0) {
      const double root = std::sqrt(discriminant);
      for (double t : {(-b - root) / a, (-b + root) / a}) {
        const double z = origin.z() + t * direction.z();
        if (t > kMinHitDistance_m && t < best && z >= z_low && z <= z_high) best = t;
      }
    }
  }
  // Caps: the planes z = z_low and z = z_high inside the radius.
  if (std::abs(direction.z()) > 1e-15) {
    for (double z_cap : {z_low, z_high}) {
      const double t = (z_cap - origin.z()) / direction.z();
      if (!(t > kMinHitDistance_m && t < best)) continue;
      const double x = ox + t * direction.x(), y = oy + t * direction.y();
      if (x * x + y * y <= r2) best = t;
    }
  }
  return best;
}

double intersect(const Sphere& sphere, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction) {
  const Eigen::Vector3d oc = origin - sphere.centre_m;
  const double b = oc.dot(direction);
  const double c = oc.squaredNorm() - sphere.radius_m * sphere.radius_m;
  const double discriminant = b * b - c;
  if (discriminant < 0.0) return kNoHit;
  const double root = std::sqrt(discriminant);
  if (-b - root > kMinHitDistance_m) return -b - root;
  if (-b + root > kMinHitDistance_m) return -b + root;
  return kNoHit;
}

double intersect(const Triangle& triangle, const Eigen::Vector3d& origin,
                 const Eigen::Vector3d& direction) {
  // Moeller-Trumbore: barycentric coordinates and distance from one 3x3 solve by Cramer's rule.
  const Eigen::Vector3d edge1 = triangle.b_m - triangle.a_m, edge2 = triangle.c_m - triangle.a_m;
  const Eigen::Vector3d p = direction.cross(edge2);
  const double determinant = edge1.dot(p);
  if (std::abs(determinant) < 1e-15) return kNoHit;  // ray parallel to the triangle
  const double inverse = 1.0 / determinant;
  const Eigen::Vector3d s = origin - triangle.a_m;
  const double u = s.dot(p) * inverse;
  if (u < 0.0 || u > 1.0) return kNoHit;
  const Eigen::Vector3d q = s.cross(edge1);
  const double v = direction.dot(q) * inverse;
  if (v < 0.0 || u + v > 1.0) return kNoHit;
  const double t = edge2.dot(q) * inverse;
  return t > kMinHitDistance_m ? t : kNoHit;
}

void World::bounds_of(const Reference& reference, Eigen::Vector3d* low,
                      Eigen::Vector3d* high) const {
  switch (reference.kind) {
    case Kind::kBox: {
      const Box& box = boxes_[reference.index];
      const Eigen::Vector3d extent = box.rotation.cwiseAbs() * box.half_extent_m;
      *low = box.centre_m - extent;
      *high = box.centre_m + extent;
      return;
    }
    case Kind::kCylinder: {
      const Cylinder& cylinder = cylinders_[reference.index];
      const Eigen::Vector3d radius(cylinder.radius_m, cylinder.radius_m, 0.0);
      *low = cylinder.base_centre_m - radius;
      *high = cylinder.base_centre_m + radius + Eigen::Vector3d(0.0, 0.0, cylinder.height_m);
      return;
    }
    case Kind::kSphere: {
      const Sphere& sphere = spheres_[reference.index];
      *low = sphere.centre_m - Eigen::Vector3d::Constant(sphere.radius_m);
      *high = sphere.centre_m + Eigen::Vector3d::Constant(sphere.radius_m);
      return;
    }
    case Kind::kTriangle: {
      const Triangle& triangle = triangles_[reference.index];
      *low = triangle.a_m.cwiseMin(triangle.b_m).cwiseMin(triangle.c_m);
      *high = triangle.a_m.cwiseMax(triangle.b_m).cwiseMax(triangle.c_m);
      return;
    }
  }
}

double World::intersect_reference(const Reference& reference, const Eigen::Vector3d& origin,
                                  const Eigen::Vector3d& direction) const {
  switch (reference.kind) {
    case Kind::kBox:
      return sim::intersect(boxes_[reference.index], origin, direction);
    case Kind::kCylinder:
      return sim::intersect(cylinders_[reference.index], origin, direction);
    case Kind::kSphere:
      return sim::intersect(spheres_[reference.index], origin, direction);
    case Kind::kTriangle:
      return sim::intersect(triangles_[reference.index], origin, direction);
  }
  return kNoHit;
}

void World::build() {
  std::vector<Reference> all;
  for (uint32_t i = 0; i < boxes_.size(); ++i) all.push_back({Kind::kBox, i});
  for (uint32_t i = 0; i < cylinders_.size(); ++i) all.push_back({Kind::kCylinder, i});
  for (uint32_t i = 0; i < spheres_.size(); ++i) all.push_back({Kind::kSphere, i});
  for (uint32_t i = 0; i < triangles_.size(); ++i) all.push_back({Kind::kTriangle, i});
  std::vector<BuildItem> items(all.size());
  for (uint32_t i = 0; i < all.size(); ++i) {
    bounds_of(all[i], &items[i].low, &items[i].high);
    items[i].centre = 0.5 * (items[i].low + items[i].high);
    items[i].reference = i;
  }
  nodes_.clear();
  nodes_.reserve(2 * items.size() / kLeafSize + 2);
  // Iterative top-down build: median split along the longest axis of the centres' bounds.
  struct Task {
    uint32_t node, first, count;
  };
  std::vector<Task> tasks;
  if (!items.empty()) {
    nodes_.emplace_back();
    tasks.push_back({0, 0, static_cast<uint32_t>(items.size())});
  }
  while (!tasks.empty()) {
    const Task task = tasks.back();
    tasks.pop_back();
    Eigen::Vector3d low = Eigen::Vector3d::Constant(kNoHit), high = -low;
    Eigen::Vector3d centre_low = low, centre_high = high;
    for (uint32_t i = task.first; i < task.first + task.count; ++i) {
      low = low.cwiseMin(items[i].low);
      high = high.cwiseMax(items[i].high);
      centre_low = centre_low.cwiseMin(items[i].centre);
      centre_high = centre_high.cwiseMax(items[i].centre);
    }
    nodes_[task.node].low = low;
    nodes_[task.node].high = high;
    if (task.count <= kLeafSize) {
      nodes_[task.node].first = task.first;
      nodes_[task.node].count = task.count;
      continue;
    }
    int axis = 0;
    (centre_high - centre_low).maxCoeff(&axis);
    const uint32_t half = task.count / 2;
    std::nth_element(
        items.begin() + task.first, items.begin() + task.first + half,
        items.begin() + task.first + task.count,
        [axis](const BuildItem& a, const BuildItem& b) { return a.centre[axis] < b.centre[axis]; });
    const uint32_t left = static_cast<uint32_t>(nodes_.size());
    nodes_.emplace_back();
    nodes_.emplace_back();
    nodes_[task.node].first = left;
    nodes_[task.node].right = left + 1;
    nodes_[task.node].count = 0;
    tasks.push_back({left, task.first, half});
    tasks.push_back({left + 1, task.first + half, task.count - half});
  }
  references_.resize(items.size());
  for (size_t i = 0; i < items.size(); ++i) references_[i] = all[items[i].reference];
  built_ = true;
}

double World::intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                        double max_range_m) const {
  if (!built_) throw Error("sim::World::intersect: call build() after adding primitives");
  double best = max_range_m;
  for (const Plane& plane : planes_)
    best = std::min(best, sim::intersect(plane, origin, direction));
  if (!nodes_.empty()) {
    const Eigen::Vector3d inverse_direction = direction.cwiseInverse();
    uint32_t stack[64];
    int depth = 0;
    stack[depth++] = 0;
    while (depth > 0) {
      const Node& node = nodes_[stack[--depth]];
      if (slab_entry(node.low, node.high, origin, inverse_direction, best) == kNoHit) continue;
      if (node.count > 0) {
        for (uint32_t i = node.first; i < node.first + node.count; ++i) {
          best = std::min(best, intersect_reference(references_[i], origin, direction));
        }
      } else {
        stack[depth++] = node.right;
        stack[depth++] = node.first;
      }
    }
  }
  return best < max_range_m ? best : kNoHit;
}

map::Mesh World::to_mesh(int segments) const {
  segments = std::max(segments, 6);
  map::Mesh mesh;
  for (const Plane& plane : planes_) {
    // Any two unit vectors spanning the plane, ordered so the quad faces along the normal.
    const Eigen::Vector3d helper =
        std::abs(plane.normal.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
    const Eigen::Vector3d u = plane.normal.cross(helper).normalized() * plane.mesh_half_size_m;
    const Eigen::Vector3d v = plane.normal.cross(u);
    const Eigen::Vector3d& c = plane.point_m;
    append_quad(&mesh, c - u - v, c + u - v, c + u + v, c - u + v, plane.colour);
  }
  for (const Box& box : boxes_) {
    for (int axis = 0; axis < 3; ++axis) {
      const int ua = (axis + 1) % 3, va = (axis + 2) % 3;
      for (double sign : {1.0, -1.0}) {
        const auto corner = [&](double su, double sv) {
          Eigen::Vector3d local = Eigen::Vector3d::Zero();
          local[axis] = sign * box.half_extent_m[axis];
          local[ua] = su * box.half_extent_m[ua];
          local[va] = sv * box.half_extent_m[va];
          return Eigen::Vector3d(box.centre_m + box.rotation * local);
        };
        // Counter-clockwise seen from outside: e_u x e_v = e_axis, reversed on the negative face.
        if (sign > 0)
          append_quad(&mesh, corner(-1, -1), corner(1, -1), corner(1, 1), corner(-1, 1),
                      box.colour);
        else
          append_quad(&mesh, corner(-1, 1), corner(1, 1), corner(1, -1), corner(-1, -1),
                      box.colour);
      }
    }
  }
  for (const Cylinder& cylinder : cylinders_) {
    const Eigen::Vector3d bottom = cylinder.base_centre_m;
    const Eigen::Vector3d top = bottom + Eigen::Vector3d(0.0, 0.0, cylinder.height_m);
    for (int i = 0; i < segments; ++i) {
      const double a0 = 2.0 * kPi * i / segments, a1 = 2.0 * kPi * (i + 1) / segments;
      const Eigen::Vector3d r0(cylinder.radius_m * std::cos(a0), cylinder.radius_m * std::sin(a0),
                               0.0);
      const Eigen::Vector3d r1(cylinder.radius_m * std::cos(a1), cylinder.radius_m * std::sin(a1),
                               0.0);
      append_quad(&mesh, bottom + r0, bottom + r1, top + r1, top + r0, cylinder.colour);
      append_triangle(&mesh, top, top + r0, top + r1, cylinder.colour);
      append_triangle(&mesh, bottom, bottom + r1, bottom + r0, cylinder.colour);
    }
  }
  for (const Sphere& sphere : spheres_) {
    const int rings = std::max(3, segments / 2);
    const auto point = [&](int ring, int i) {
      const double polar = kPi * ring / rings, azimuth = 2.0 * kPi * i / segments;
      return Eigen::Vector3d(sphere.centre_m +
                             sphere.radius_m * Eigen::Vector3d(std::sin(polar) * std::cos(azimuth),
                                                               std::sin(polar) * std::sin(azimuth),
                                                               std::cos(polar)));
    };
    for (int ring = 0; ring < rings; ++ring) {
      for (int i = 0; i < segments; ++i) {
        // e_polar x e_azimuth = e_radial: outward. The pole rows each lose one degenerate triangle.
        if (ring + 1 < rings)
          append_triangle(&mesh, point(ring, i), point(ring + 1, i), point(ring + 1, i + 1),
                          sphere.colour);
        if (ring > 0)
          append_triangle(&mesh, point(ring, i), point(ring + 1, i + 1), point(ring, i + 1),
                          sphere.colour);
      }
    }
  }
  for (const Triangle& triangle : triangles_) {
    append_triangle(&mesh, triangle.a_m, triangle.b_m, triangle.c_m, triangle.colour);
  }
  return mesh;
}

}  // namespace sim
}  // namespace covox

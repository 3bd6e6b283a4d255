#pragma once
// Analytic test scenes (plane, sphere, box) with exact signed distance and ray intersection, and
// simulated sensors that see them: the independent reference for TSDF/ESDF/mesh tests.
#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <vector>

#include "covoxslam/core/vec3.h"

namespace covox {
namespace testing_support {

enum class Shape { kPlane, kSphere, kBox };

// Signed distance is positive in free space (where the sensor is). For the sphere and the box
// the sensor is inside: a hollow sphere or a closed room, so the inside is free space.
struct AnalyticScene {
  Shape shape = Shape::kSphere;
  Eigen::Vector3d center{0.0, 0.0, 0.0};
  double radius = 4.0;                          // sphere
  Eigen::Vector3d half_extent{4.0, 3.0, 2.5};   // box (room)
  Eigen::Vector3d plane_normal{0.0, 0.0, 1.0};  // plane through `center`, free side along normal

  double signed_distance(const Eigen::Vector3d& p) const {
    switch (shape) {
      case Shape::kPlane:
        return (p - center).dot(plane_normal);
      case Shape::kSphere:
        return radius - (p - center).norm();
      case Shape::kBox: {
        const Eigen::Vector3d d = (p - center).cwiseAbs();
        const Eigen::Vector3d gap = half_extent - d;  // positive inside the room
        if ((gap.array() >= 0).all()) return gap.minCoeff();
        return -(-gap).cwiseMax(0.0).norm();
      }
    }
    return 0.0;
  }

  // Unit surface normal (towards free space) from the analytic SDF's gradient.
  Eigen::Vector3d normal(const Eigen::Vector3d& p) const {
    const double h = 1e-5;
    Eigen::Vector3d gradient;
    for (int axis = 0; axis < 3; ++axis) {
      Eigen::Vector3d step = Eigen::Vector3d::Zero();
      step[axis] = h;
      gradient[axis] = (signed_distance(p + step) - signed_distance(p - step)) / (2 * h);
    }
    return gradient.normalized();
  }

  // Angle between a ray and the surface normal where it hits, in degrees.
  double incidence_deg(const Eigen::Vector3d& hit, const Eigen::Vector3d& direction) const {
    const double cosine = std::min(1.0, std::abs(direction.dot(normal(hit))));
    return std::acos(cosine) * 180.0 / 3.14159265358979323846;
  }

  // Distance along a unit ray to the surface, or infinity.
  double intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction) const {
    const double inf = std::numeric_limits<double>::infinity();
    switch (shape) {
      case Shape::kPlane: {
        const double denominator = direction.dot(plane_normal);
        if (std::abs(denominator) < 1e-9) return inf;
        const double t = (center - origin).dot(plane_normal) / denominator;
        return t > 0 ? t : inf;
      }
      case Shape::kSphere: {
        const Eigen::Vector3d oc = origin - center;
        const double b = oc.dot(direction), c = oc.squaredNorm() - radius * radius;
        const double discriminant = b * b - c;
        if (discriminant < 0) return inf;
        const double t = -b + std::sqrt(discriminant);  // exit point: the sensor is inside
        return t > 0 ? t : inf;
      }
      case Shape::kBox: {
        double t_exit = inf;
        for (int axis = 0; axis < 3; ++axis) {
          if (std::abs(direction[axis]) < 1e-12) continue;
          const double wall =
              center[axis] + (direction[axis] > 0 ? half_extent[axis] : -half_extent[axis]);
          t_exit = std::min(t_exit, (wall - origin[axis]) / direction[axis]);
        }
        return t_exit > 0 ? t_exit : inf;
      }
    }
    return inf;
  }
};

// A spinning LiDAR: `columns` azimuths x `rows` elevations in [-fov/2, fov/2]. Returns hitting
// the surface more obliquely than max_incidence_deg are left out when it is below 90.
inline std::vector<Vec3f> simulate_lidar(const AnalyticScene& scene,
                                         const Eigen::Isometry3d& T_world_sensor, int columns,
                                         int rows, double vertical_fov_deg, double max_range_m,
                                         double max_incidence_deg = 90.0) {
  std::vector<Vec3f> points;
  const double pi = 3.14159265358979323846;
  for (int r = 0; r < rows; ++r) {
    const double elevation = (-0.5 + (r + 0.5) / rows) * vertical_fov_deg * pi / 180.0;
    for (int c = 0; c < columns; ++c) {
      const double azimuth = 2.0 * pi * c / columns;
      const Eigen::Vector3d direction_sensor(std::cos(elevation) * std::cos(azimuth),
                                             std::cos(elevation) * std::sin(azimuth),
                                             std::sin(elevation));
      const Eigen::Vector3d direction_world = T_world_sensor.linear() * direction_sensor;
      const double t = scene.intersect(T_world_sensor.translation(), direction_world);
      if (!(t < max_range_m)) continue;
      const Eigen::Vector3d hit = T_world_sensor.translation() + direction_world * t;
      if (max_incidence_deg < 90.0 && scene.incidence_deg(hit, direction_world) > max_incidence_deg)
        continue;
      const Eigen::Vector3d p = direction_sensor * t;
      points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()),
                          static_cast<float>(p.z()));
    }
  }
  return points;
}

// A pinhole depth camera looking along its +z; returns depth in millimetres (0 = no return).
inline std::vector<uint16_t> simulate_depth_mm(const AnalyticScene& scene,
                                               const Eigen::Isometry3d& T_world_camera, int width,
                                               int height, double fx, double fy, double cx,
                                               double cy, double max_incidence_deg = 90.0) {
  std::vector<uint16_t> depth(static_cast<size_t>(width) * height, 0);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3d ray_camera((u - cx) / fx, (v - cy) / fy, 1.0);
      const Eigen::Vector3d direction_world = T_world_camera.linear() * ray_camera.normalized();
      const double t = scene.intersect(T_world_camera.translation(), direction_world);
      if (!(t < 60.0)) continue;
      const Eigen::Vector3d hit = T_world_camera.translation() + direction_world * t;
      if (max_incidence_deg < 90.0 && scene.incidence_deg(hit, direction_world) > max_incidence_deg)
        continue;
      const double z = t / ray_camera.norm();  // depth is the z coordinate, not the range
      depth[static_cast<size_t>(v) * width + u] = static_cast<uint16_t>(std::lround(z * 1000.0));
    }
  }
  return depth;
}

}  // namespace testing_support
}  // namespace covox

#pragma once
// A closed room with solid spheres and boxes inside: random obstacle scenes for ESDF tests.
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "covoxslam/core/vec3.h"

namespace covox {
namespace testing_support {

struct ObstacleScene {
  Eigen::Vector3d room_half_extent{3.0, 2.5, 1.5};
  struct Sphere {
    Eigen::Vector3d center;
    double radius;
  };
  struct Box {
    Eigen::Vector3d center;
    Eigen::Vector3d half_extent;
  };
  std::vector<Sphere> spheres;
  std::vector<Box> boxes;

  static ObstacleScene random(uint32_t seed, int spheres, int boxes) {
    ObstacleScene scene;
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> x(-2.2, 2.2), y(-1.8, 1.8), z(-1.0, 1.0),
        size(0.15, 0.45);
    for (int i = 0; i < spheres; ++i)
      scene.spheres.push_back({{x(random), y(random), z(random)}, size(random)});
    for (int i = 0; i < boxes; ++i) {
      scene.boxes.push_back(
          {{x(random), y(random), z(random)}, {size(random), size(random), size(random)}});
    }
    return scene;
  }

  // Ray entry distance into a solid box (slab method), or infinity.
  static double enter_box(const Box& box, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
    double t_near = -std::numeric_limits<double>::infinity(),
           t_far = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
      if (std::abs(d[a]) < 1e-12) {
        if (std::abs(o[a] - box.center[a]) > box.half_extent[a])
          return std::numeric_limits<double>::infinity();
        continue;
      }
      double t1 = (box.center[a] - box.half_extent[a] - o[a]) / d[a];
      double t2 = (box.center[a] + box.half_extent[a] - o[a]) / d[a];
      if (t1 > t2) std::swap(t1, t2);
      t_near = std::max(t_near, t1);
      t_far = std::min(t_far, t2);
    }
    return (t_near <= t_far && t_near > 0) ? t_near : std::numeric_limits<double>::infinity();
  }

  double intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
    double t = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {  // room walls: exit of the room box
      if (std::abs(d[a]) < 1e-12) continue;
      t = std::min(t, ((d[a] > 0 ? room_half_extent[a] : -room_half_extent[a]) - o[a]) / d[a]);
    }
    for (const Sphere& s : spheres) {
      const Eigen::Vector3d oc = o - s.center;
      const double b = oc.dot(d), c = oc.squaredNorm() - s.radius * s.radius, disc = b * b - c;
      if (disc >= 0 && -b - std::sqrt(disc) > 0) t = std::min(t, -b - std::sqrt(disc));
    }
    for (const Box& box : boxes) t = std::min(t, enter_box(box, o, d));
    return t;
  }

  bool inside_obstacle(const Eigen::Vector3d& p) const {
    for (const Sphere& s : spheres) {
      if ((p - s.center).norm() < s.radius) return true;
    }
    for (const Box& b : boxes) {
      if (((p - b.center).cwiseAbs() - b.half_extent).maxCoeff() < 0) return true;
    }
    return false;
  }

  std::vector<Vec3f> lidar(const Eigen::Isometry3d& T_world_sensor, int columns, int rows) const {
    std::vector<Vec3f> points;
    const double pi = 3.14159265358979323846;
    for (int r = 0; r < rows; ++r) {
      const double elevation = (-0.5 + (r + 0.5) / rows) * pi * 0.9;
      for (int c = 0; c < columns; ++c) {
        const double azimuth = 2.0 * pi * c / columns;
        const Eigen::Vector3d ds(std::cos(elevation) * std::cos(azimuth),
                                 std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
        const double t = intersect(T_world_sensor.translation(), T_world_sensor.linear() * ds);
        if (!std::isfinite(t)) continue;
        const Eigen::Vector3d p = ds * t;
        points.emplace_back(float(p.x()), float(p.y()), float(p.z()));
      }
    }
    return points;
  }
};

}  // namespace testing_support
}  // namespace covox

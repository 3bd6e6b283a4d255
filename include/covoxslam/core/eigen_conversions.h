#pragma once
// Host-side conversions between Eigen (used at the API boundary) and the kernel math types.
#include <Eigen/Geometry>

#include "covoxslam/core/vec3.h"

namespace covox {

inline Transform3f to_transform3f(const Eigen::Isometry3d& pose) {
  Transform3f transform;
  const Eigen::Matrix3d rotation = pose.linear();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) transform.rotation[3 * r + c] = static_cast<float>(rotation(r, c));
  }
  transform.translation =
      Vec3f(static_cast<float>(pose.translation().x()), static_cast<float>(pose.translation().y()),
            static_cast<float>(pose.translation().z()));
  return transform;
}

inline Vec3f to_vec3f(const Eigen::Vector3d& v) {
  return Vec3f(static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z()));
}

}  // namespace covox

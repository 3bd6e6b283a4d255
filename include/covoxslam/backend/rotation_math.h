#pragma once
// SO(3) helpers for the pose-graph kernels, usable on the host and on the device. Quaternions are
// stored as four doubles in Eigen's order (x, y, z, w) and are unit length.
#include <Eigen/Core>
#include <cmath>

#include "covoxslam/core/macros.h"

namespace covox {
namespace backend {

using Matrix3d = Eigen::Matrix<double, 3, 3>;
using Vector3d = Eigen::Matrix<double, 3, 1>;

COVOX_HD_INLINE Matrix3d skew(const Vector3d& v) {
  Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

COVOX_HD_INLINE Matrix3d quaternion_to_rotation(const double* q) {
  const double x = q[0], y = q[1], z = q[2], w = q[3];
  Matrix3d r;
  r << 1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),  //
      2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),   //
      2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y);
  return r;
}

// out = a * b (Hamilton product); out may not alias a or b.
COVOX_HD_INLINE void quaternion_multiply(const double* a, const double* b, double* out) {
  out[0] = a[3] * b[0] + b[3] * a[0] + a[1] * b[2] - a[2] * b[1];
  out[1] = a[3] * b[1] + b[3] * a[1] + a[2] * b[0] - a[0] * b[2];
  out[2] = a[3] * b[2] + b[3] * a[2] + a[0] * b[1] - a[1] * b[0];
  out[3] = a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2];
}

COVOX_HD_INLINE void quaternion_conjugate(const double* q, double* out) {
  out[0] = -q[0];
  out[1] = -q[1];
  out[2] = -q[2];
  out[3] = q[3];
}

// The quaternion of the rotation vector `v` (angle |v| about v / |v|).
COVOX_HD_INLINE void rotation_vector_to_quaternion(const Vector3d& v, double* q) {
  const double theta_sq = v.squaredNorm();
  const double theta = sqrt(theta_sq);
  // sin(theta/2)/theta loses all digits as theta -> 0: use its series there.
  const double k = theta < 1e-4 ? 0.5 - theta_sq / 48.0 : sin(0.5 * theta) / theta;
  q[0] = k * v.x();
  q[1] = k * v.y();
  q[2] = k * v.z();
  q[3] = cos(0.5 * theta);
}

// The rotation vector of a unit quaternion, angle in [0, pi] (q and -q give the same result).
COVOX_HD_INLINE Vector3d quaternion_to_rotation_vector(const double* q) {
  double w = q[3];
  Vector3d v(q[0], q[1], q[2]);
  if (w < 0.0) {  // the shorter way round
    w = -w;
    v = -v;
  }
  const double sin_half_sq = v.squaredNorm();
  const double sin_half = sqrt(sin_half_sq);
  // 2 atan2(s, w) / s -> 2 / w (1 - s^2 / (3 w^2)) for small s.
  const double k = sin_half < 1e-5 ? 2.0 / w * (1.0 - sin_half_sq / (3.0 * w * w))
                                   : 2.0 * atan2(sin_half, w) / sin_half;
  return k * v;
}

// Inverse of the right Jacobian of SO(3) at the rotation vector `phi`:
//   log(Exp(phi) Exp(d)) = phi + Jr^-1(phi) d + O(|d|^2).
COVOX_HD_INLINE Matrix3d right_jacobian_inverse(const Vector3d& phi) {
  const double a_sq = phi.squaredNorm();
  const double a = sqrt(a_sq);
  // 1/a^2 - cot(a/2) / (2a): well conditioned up to a = pi, a series near 0.
  const double c =
      a < 1e-4 ? 1.0 / 12.0 + a_sq / 720.0 : 1.0 / a_sq - cos(0.5 * a) / (2.0 * a * sin(0.5 * a));
  const Matrix3d k = skew(phi);
  return Matrix3d::Identity() + 0.5 * k + c * (k * k);
}

// Angle wrapped into [-pi, pi).
COVOX_HD_INLINE double wrap_angle(double angle) {
  constexpr double kTwoPi = 6.283185307179586476925286766559;
  constexpr double kPi = 3.1415926535897932384626433832795;
  return angle - kTwoPi * floor((angle + kPi) / kTwoPi);
}

}  // namespace backend
}  // namespace covox

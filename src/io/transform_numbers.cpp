#include "covoxslam/io/transform_numbers.h"

#include <cmath>
#include <cstdio>

#include "covoxslam/core/error.h"
#include "covoxslam/io/internal/text_numbers.h"

namespace covox {
namespace io {
namespace {

constexpr double kUnitTolerance = 1e-3;

bool is_rigid(const Eigen::Matrix4d& M) {
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  return (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <=
             kUnitTolerance &&
         R.determinant() > 0.0 && M.row(3).head<3>().cwiseAbs().sum() <= 1e-9 &&
         std::abs(M(3, 3) - 1.0) <= 1e-9;
}

}  // namespace

Eigen::Isometry3d transform_from_numbers(const std::vector<double>& values,
                                         const std::string& what) {
  for (double v : values) {
    if (!std::isfinite(v)) throw Error(what + ": contains a non-finite number");
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (values.size() == 7) {
    const Eigen::Quaterniond q(values[6], values[3], values[4], values[5]);
    if (std::abs(q.norm() - 1.0) > kUnitTolerance)
      throw Error(what + ": the quaternion (qx, qy, qz, qw) is not of unit length");
    T.linear() = q.normalized().toRotationMatrix();
    T.translation() = Eigen::Vector3d(values[0], values[1], values[2]);
    return T;
  }
  if (values.size() == 16) {
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) M(r, c) = values[4 * r + c];
    }
    if (!is_rigid(M)) throw Error(what + ": the 4x4 matrix is not a rigid transform");
    T.matrix() = M;
    return T;
  }
  throw Error(what + ": expected 7 numbers [x, y, z, qx, qy, qz, qw] or 16 (a row-major 4x4 " +
              "matrix), got " + std::to_string(values.size()));
}

Eigen::Isometry3d transform_from_text(const std::string& text, const std::string& what) {
  std::string list = text;
  const size_t open = list.find_first_not_of(" \t");
  const size_t close = list.find_last_not_of(" \t");
  if (open != std::string::npos && list[open] == '[' && list[close] == ']') {
    list = list.substr(open + 1, close - open - 1);
  }
  for (char& c : list) {
    if (c == ',') c = ' ';
  }
  std::vector<double> values;
  for (const std::string_view token : split_whitespace(list)) {
    double value = 0.0;
    if (!parse_double(token, &value)) {
      throw Error(what + ": '" + std::string(token) + "' in '" + text + "' is not a number");
    }
    values.push_back(value);
  }
  return transform_from_numbers(values, what);
}

std::string transform_to_text(const Eigen::Isometry3d& T) {
  Eigen::Quaterniond q(T.linear());
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  char text[160];
  std::snprintf(text, sizeof(text), "%.6f %.6f %.6f %.6f %.6f %.6f %.6f", T.translation().x(),
                T.translation().y(), T.translation().z(), q.x(), q.y(), q.z(), q.w());
  return text;
}

}  // namespace io
}  // namespace covox

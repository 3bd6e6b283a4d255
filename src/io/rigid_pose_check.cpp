#include "covoxslam/io/rigid_pose_check.h"

#include <Eigen/SVD>

#include <cmath>
#include <sstream>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace {

// The bottom row of a homogeneous matrix is written as exact 0/1 by every tool we know; 1e-6
// still lets through files that printed "-0.000000" style noise.
constexpr double kBottomRowTolerance = 1e-6;

std::string format_number(double value) {
  std::ostringstream stream;
  stream.precision(3);
  stream << value;
  return stream.str();
}

void count_repair(ReadStats* stats) {
  if (stats != nullptr) ++stats->reorthonormalized_poses;
}

}  // namespace

double orthonormality_error(const Eigen::Matrix3d& rotation) {
  return (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
}

Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& matrix) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(matrix, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d sign_fix = Eigen::Matrix3d::Identity();
  // U V^T is the nearest orthogonal matrix; flipping the axis of the smallest singular value
  // keeps it a proper rotation (det +1) if the input was close to a reflection.
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0) sign_fix(2, 2) = -1.0;
  return svd.matrixU() * sign_fix * svd.matrixV().transpose();
}

Eigen::Isometry3d make_rigid_pose(const Eigen::Matrix3d& rotation,
                                  const Eigen::Vector3d& translation, const std::string& where,
                                  ReadStats* stats, const PoseTolerances& tolerances) {
  if (!rotation.allFinite() || !translation.allFinite()) {
    throw Error(where + ": pose has a non-finite value (NaN or Inf)");
  }
  const double determinant = rotation.determinant();
  if (!(determinant > 0.0)) {
    throw Error(where + ": rotation has determinant " + format_number(determinant) +
                " (a reflection or degenerate matrix, not a rotation)");
  }
  const double error = orthonormality_error(rotation);
  if (error > tolerances.reject_above_error) {
    throw Error(where +
                ": rotation is far from orthonormal (max |R^T R - I| = " + format_number(error) +
                ", limit " + format_number(tolerances.reject_above_error) + ")");
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = translation;
  if (error > tolerances.reorthonormalize_above_error) {
    pose.linear() = nearest_rotation(rotation);
    count_repair(stats);
  } else {
    pose.linear() = rotation;
  }
  return pose;
}

Eigen::Isometry3d make_rigid_pose(const Eigen::Matrix4d& matrix, const std::string& where,
                                  ReadStats* stats, const PoseTolerances& tolerances) {
  if (!matrix.allFinite()) throw Error(where + ": pose has a non-finite value (NaN or Inf)");
  const Eigen::RowVector4d bottom_row = matrix.row(3);
  if ((bottom_row - Eigen::RowVector4d(0.0, 0.0, 0.0, 1.0)).cwiseAbs().maxCoeff() >
      kBottomRowTolerance) {
    std::ostringstream row_text;
    row_text << bottom_row;
    throw Error(where + ": bottom row of the 4x4 pose is (" + row_text.str() +
                "), expected (0 0 0 1): not a rigid transform");
  }
  return make_rigid_pose(matrix.topLeftCorner<3, 3>(), matrix.topRightCorner<3, 1>(), where, stats,
                         tolerances);
}

Eigen::Isometry3d make_rigid_pose_from_quaternion(const Eigen::Vector3d& translation, double qx,
                                                  double qy, double qz, double qw,
                                                  const std::string& where, ReadStats* stats,
                                                  const PoseTolerances& tolerances) {
  Eigen::Quaterniond rotation(qw, qx, qy, qz);
  if (!translation.allFinite() || !rotation.coeffs().allFinite()) {
    throw Error(where + ": pose has a non-finite value (NaN or Inf)");
  }
  const double norm_error = std::abs(rotation.norm() - 1.0);
  if (norm_error > tolerances.reject_above_error) {
    throw Error(where + ": quaternion norm is " + format_number(rotation.norm()) +
                ", too far from 1 to be a rotation");
  }
  if (norm_error > tolerances.reorthonormalize_above_error) count_repair(stats);
  // Normalised unconditionally: Eigen's toRotationMatrix assumes a unit quaternion.
  rotation.normalize();
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rotation.toRotationMatrix();
  pose.translation() = translation;
  return pose;
}

}  // namespace io
}  // namespace covox

#include "covoxslam/pipeline/external_constraints.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

}  // namespace

std::string information_problem(const Eigen::MatrixXd& information) {
  if (information.rows() != information.cols()) return "the information matrix is not square";
  if (!information.allFinite()) return "the information matrix is not finite";
  const double scale = information.cwiseAbs().maxCoeff();
  if (!(scale > 0.0)) return "the information matrix is zero";
  if ((information - information.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) {
    return "the information matrix is not symmetric";
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(
      0.5 * (information + information.transpose()), Eigen::EigenvaluesOnly);
  // Round-off of a rank-deficient matrix gives eigenvalues of about -1e-16 * scale.
  if (eigen.eigenvalues().minCoeff() < -1e-9 * scale) {
    return "the information matrix is not positive semi-definite (smallest eigenvalue " +
           std::to_string(eigen.eigenvalues().minCoeff()) + ")";
  }
  return {};
}

std::string loop_closure_problem(const LoopClosure& closure) {
  if (!std::isfinite(closure.from_stamp_s) || !std::isfinite(closure.to_stamp_s))
    return "a stamp is not finite";
  if (!is_valid_rigid_pose(closure.T_from_to))
    return "the transform is not a finite rigid transform";
  return information_problem(closure.information);
}

RelativeConstraint4Dof project_loop_closure(const Eigen::Isometry3d& T_Sa_from,
                                            const Eigen::Isometry3d& T_from_to,
                                            const Eigen::Isometry3d& T_Sb_to,
                                            const Eigen::Matrix<double, 6, 6>& information) {
  const Eigen::Isometry3d T_to_Sb = T_Sb_to.inverse();
  const Eigen::Isometry3d T_Sa_Sb = T_Sa_from * T_from_to * T_to_Sb;
  RelativeConstraint4Dof result;
  result.measurement = pose_4dof_from_isometry(T_Sa_Sb);

  // e = K d (see the header): d = (dt, dtheta) in the `from` frame, e = (e_t, e_theta) in Sa.
  const Eigen::Matrix3d R_a = T_Sa_from.linear();
  Eigen::Matrix<double, 6, 6> K = Eigen::Matrix<double, 6, 6>::Zero();
  K.topLeftCorner<3, 3>() = R_a;
  K.topRightCorner<3, 3>() = -R_a * skew(T_from_to.linear() * T_to_Sb.translation());
  K.bottomRightCorner<3, 3>() = R_a;
  const Eigen::Matrix<double, 6, 6> K_inverse =
      K.inverse();  // block triangular with rotations: exact
  const Eigen::Matrix<double, 6, 6> information_e = K_inverse.transpose() * information * K_inverse;

  // Reorder to wanted (e_t, e_theta_z) and nuisance (e_theta_x, e_theta_y), then marginalise.
  const int wanted[4] = {0, 1, 2, 5};
  const int nuisance[2] = {3, 4};
  Eigen::Matrix4d L_ww;
  Eigen::Matrix<double, 4, 2> L_wn;
  Eigen::Matrix2d L_nn;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) L_ww(r, c) = information_e(wanted[r], wanted[c]);
    for (int c = 0; c < 2; ++c) L_wn(r, c) = information_e(wanted[r], nuisance[c]);
  }
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 2; ++c) L_nn(r, c) = information_e(nuisance[r], nuisance[c]);
  }
  // Pseudo-inverse of the symmetric 2x2 block through its eigen-decomposition: directions without
  // information (eigenvalue ~0) are simply not marginalised over (they couple to nothing).
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(0.5 * (L_nn + L_nn.transpose()));
  const double largest = std::max(eigen.eigenvalues().cwiseAbs().maxCoeff(), 0.0);
  Eigen::Matrix2d L_nn_pinv = Eigen::Matrix2d::Zero();
  for (int k = 0; k < 2; ++k) {
    const double value = eigen.eigenvalues()(k);
    if (value > 1e-12 * largest && value > 0.0) {
      L_nn_pinv += eigen.eigenvectors().col(k) * eigen.eigenvectors().col(k).transpose() / value;
    }
  }
  const Eigen::Matrix4d marginal = L_ww - L_wn * L_nn_pinv * L_wn.transpose();
  result.information = 0.5 * (marginal + marginal.transpose());
  return result;
}

}  // namespace pipeline
}  // namespace covox

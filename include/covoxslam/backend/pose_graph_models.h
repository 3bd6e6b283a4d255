#pragma once
// Residuals and analytic Jacobians of the pose-graph constraints, one "model" per mode (Se3Model,
// FourDofModel below, each with its residual). The solver is written once over a model:
//   Model::kDim                  tangent dimension D of a pose (6 or 4)
//   Model::Pose / ::Constraint   the types of pose_graph_types.h
//   Model::evaluate(c, poses, f, Ji, Jj)   whitened residual f = S r (D values) and its Jacobians
//                                with respect to the tangent updates of poses[c.from] and
//                                poses[c.to] (D x D, row-major; Jj is zero for unary constraints)
//   Model::plus(pose, delta)     the pose moved by a tangent step
#include <Eigen/Core>

#include "covoxslam/backend/pose_graph_types.h"
#include "covoxslam/backend/rotation_math.h"
#include "covoxslam/core/macros.h"

namespace covox {
namespace backend {

// f = S r, J <- S J for a D-dimensional residual (S row-major).
template <int D>
COVOX_HD_INLINE void whiten(const double* sqrt_information, double* residual, double* jac_i,
                            double* jac_j) {
  using Square = Eigen::Matrix<double, D, D, Eigen::RowMajor>;
  using Vector = Eigen::Matrix<double, D, 1>;
  const Eigen::Map<const Square> s(sqrt_information);
  Eigen::Map<Vector> r(residual);
  const Vector whitened = s * r;
  r = whitened;
  Eigen::Map<Square> ji(jac_i), jj(jac_j);
  const Square wi = s * ji;
  const Square wj = s * jj;
  ji = wi;
  jj = wj;
}

// 0.5 |S r|^2 without forming the whitened residual.
template <int D>
COVOX_HD_INLINE double half_squared_whitened_norm(const double* sqrt_information, const double* r) {
  double sum = 0.0;
  for (int row = 0; row < D; ++row) {
    double v = 0.0;
    for (int col = 0; col < D; ++col) v += sqrt_information[row * D + col] * r[col];
    sum += v * v;
  }
  return 0.5 * sum;
}

// SE(3) residual (documented choice, the Ceres oracle in the tests uses the same one):
//   E = Z_ij^-1 * T_i^-1 * T_j,   r = [ t(E) ; log(R(E)) ]   (translation first, as g2o orders its
//   information matrix; log is the rotation vector with angle in [0, pi]).
// SE(3) update: t <- t + dt, R <- R Exp(dtheta) (rotation perturbed on the right).
struct Se3Model {
  static constexpr int kDim = 6;
  using Pose = Se3Pose;
  using Constraint = Se3Constraint;

  // The unwhitened residual r only (the cost path does not need Jacobians).
  COVOX_HD static void raw_residual(const Constraint& c, const Pose& pi, const Pose& pj,
                                    double* r) {
    const Matrix3d ri = quaternion_to_rotation(pi.rotation);
    const Matrix3d rz = quaternion_to_rotation(c.measurement.rotation);
    const Vector3d d(pj.translation[0] - pi.translation[0], pj.translation[1] - pi.translation[1],
                     pj.translation[2] - pi.translation[2]);
    const Vector3d tz(c.measurement.translation[0], c.measurement.translation[1],
                      c.measurement.translation[2]);
    const Vector3d t_error = rz.transpose() * (ri.transpose() * d - tz);
    const Vector3d rotation_error = rotation_error_vector(c, pi, pj);
    for (int k = 0; k < 3; ++k) {
      r[k] = t_error(k);
      r[3 + k] = rotation_error(k);
    }
  }

  COVOX_HD static void evaluate(const Constraint& c, const Pose* poses, double* f, double* jac_i,
                                double* jac_j) {
    const Pose& pi = poses[c.from];
    const Pose& pj = poses[c.to];
    const Matrix3d ri = quaternion_to_rotation(pi.rotation);
    const Matrix3d rj = quaternion_to_rotation(pj.rotation);
    const Matrix3d rz = quaternion_to_rotation(c.measurement.rotation);
    const Vector3d d(pj.translation[0] - pi.translation[0], pj.translation[1] - pi.translation[1],
                     pj.translation[2] - pi.translation[2]);
    const Vector3d tz(c.measurement.translation[0], c.measurement.translation[1],
                      c.measurement.translation[2]);
    const Vector3d a = ri.transpose() * d;  // p_j in frame i
    const Vector3d t_error = rz.transpose() * (a - tz);
    const Vector3d phi = rotation_error_vector(c, pi, pj);
    const Matrix3d jr_inv = right_jacobian_inverse(phi);
    const Matrix3d rzt_rit = rz.transpose() * ri.transpose();

    using Block = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;
    Eigen::Map<Block> ji(jac_i), jj(jac_j);
    ji.setZero();
    jj.setZero();
    // d t(E): -Rz^T Ri^T dt_i + Rz^T [a]x dtheta_i + Rz^T Ri^T dt_j.
    ji.block<3, 3>(0, 0) = -rzt_rit;
    ji.block<3, 3>(0, 3) = rz.transpose() * skew(a);
    jj.block<3, 3>(0, 0) = rzt_rit;
    // d log(R(E)): R(E) Exp(-Rj^T Ri dtheta_i) and R(E) Exp(dtheta_j).
    ji.block<3, 3>(3, 3) = -jr_inv * (rj.transpose() * ri);
    jj.block<3, 3>(3, 3) = jr_inv;
    for (int k = 0; k < 3; ++k) {
      f[k] = t_error(k);
      f[3 + k] = phi(k);
    }
    whiten<6>(c.sqrt_information, f, jac_i, jac_j);
  }

  COVOX_HD static double cost(const Constraint& c, const Pose* poses) {
    double r[6];
    raw_residual(c, poses[c.from], poses[c.to], r);
    return half_squared_whitened_norm<6>(c.sqrt_information, r);
  }

  COVOX_HD static Pose plus(const Pose& pose, const double* delta) {
    Pose out;
    for (int k = 0; k < 3; ++k) out.translation[k] = pose.translation[k] + delta[k];
    double dq[4];
    rotation_vector_to_quaternion(Vector3d(delta[3], delta[4], delta[5]), dq);
    quaternion_multiply(pose.rotation, dq, out.rotation);
    // Renormalise so that rounding never accumulates into a non-rotation.
    const double n = sqrt(out.rotation[0] * out.rotation[0] + out.rotation[1] * out.rotation[1] +
                          out.rotation[2] * out.rotation[2] + out.rotation[3] * out.rotation[3]);
    for (int k = 0; k < 4; ++k) out.rotation[k] /= n;
    return out;
  }

  // |x| for the step-size test: the translation part (rotations are bounded).
  COVOX_HD static double squared_norm(const Pose& pose) {
    return pose.translation[0] * pose.translation[0] + pose.translation[1] * pose.translation[1] +
           pose.translation[2] * pose.translation[2] + 1.0;
  }

 private:
  // log(R(E)) through quaternions: q_E = q_z^* q_i^* q_j.
  COVOX_HD static Vector3d rotation_error_vector(const Constraint& c, const Pose& pi,
                                                 const Pose& pj) {
    double zc[4], ic[4], tmp[4], qe[4];
    quaternion_conjugate(c.measurement.rotation, zc);
    quaternion_conjugate(pi.rotation, ic);
    quaternion_multiply(zc, ic, tmp);
    quaternion_multiply(tmp, pj.rotation, qe);
    return quaternion_to_rotation_vector(qe);
  }
};

// 4-DoF residuals (voxgraph's odometry form):
//   relative: r = [ Rz(yaw_i)^T (p_j - p_i) - dp ; wrap(yaw_j - yaw_i - dyaw) ]
//   absolute: r = [ p_i - p_measured ; 0 ]
// 4-DoF update: plain addition (yaw is not wrapped; residuals are).
struct FourDofModel {
  static constexpr int kDim = 4;
  using Pose = Pose4Dof;
  using Constraint = Constraint4Dof;

  COVOX_HD static void raw_residual(const Constraint& c, const Pose* poses, double* r) {
    const Pose& pi = poses[c.from];
    if (c.kind == Constraint4DofKind::kAbsolutePosition) {
      r[0] = pi.x - c.measurement.x;
      r[1] = pi.y - c.measurement.y;
      r[2] = pi.z - c.measurement.z;
      r[3] = 0.0;
      return;
    }
    const Pose& pj = poses[c.to];
    const double cs = cos(pi.yaw), sn = sin(pi.yaw);
    const double dx = pj.x - pi.x, dy = pj.y - pi.y;
    r[0] = cs * dx + sn * dy - c.measurement.x;
    r[1] = -sn * dx + cs * dy - c.measurement.y;
    r[2] = pj.z - pi.z - c.measurement.z;
    r[3] = wrap_angle(pj.yaw - pi.yaw - c.measurement.yaw);
  }

  COVOX_HD static void evaluate(const Constraint& c, const Pose* poses, double* f, double* jac_i,
                                double* jac_j) {
    raw_residual(c, poses, f);
    for (int k = 0; k < 16; ++k) {
      jac_i[k] = 0.0;
      jac_j[k] = 0.0;
    }
    if (c.kind == Constraint4DofKind::kAbsolutePosition) {
      jac_i[0] = jac_i[5] = jac_i[10] = 1.0;
    } else {
      const Pose& pi = poses[c.from];
      const Pose& pj = poses[c.to];
      const double cs = cos(pi.yaw), sn = sin(pi.yaw);
      const double dx = pj.x - pi.x, dy = pj.y - pi.y;
      // Rows: r0, r1, r2, r3; columns: x, y, z, yaw (row-major 4x4).
      jac_i[0] = -cs, jac_i[1] = -sn, jac_i[3] = -sn * dx + cs * dy;
      jac_i[4] = sn, jac_i[5] = -cs, jac_i[7] = -cs * dx - sn * dy;
      jac_i[10] = -1.0;
      jac_i[15] = -1.0;
      jac_j[0] = cs, jac_j[1] = sn;
      jac_j[4] = -sn, jac_j[5] = cs;
      jac_j[10] = 1.0;
      jac_j[15] = 1.0;
    }
    whiten<4>(c.sqrt_information, f, jac_i, jac_j);
  }

  COVOX_HD static double cost(const Constraint& c, const Pose* poses) {
    double r[4];
    raw_residual(c, poses, r);
    return half_squared_whitened_norm<4>(c.sqrt_information, r);
  }

  COVOX_HD static Pose plus(const Pose& pose, const double* delta) {
    Pose out;
    out.x = pose.x + delta[0];
    out.y = pose.y + delta[1];
    out.z = pose.z + delta[2];
    out.yaw = pose.yaw + delta[3];
    return out;
  }

  COVOX_HD static double squared_norm(const Pose& pose) {
    return pose.x * pose.x + pose.y * pose.y + pose.z * pose.z + pose.yaw * pose.yaw;
  }
};

// The vertices a constraint touches (the second is kNoVertex for unary constraints).
COVOX_HD_INLINE int32_t constraint_to(const Se3Constraint& c) { return c.to; }
COVOX_HD_INLINE int32_t constraint_to(const Constraint4Dof& c) {
  return c.kind == Constraint4DofKind::kAbsolutePosition ? kNoVertex : c.to;
}

}  // namespace backend
}  // namespace covox

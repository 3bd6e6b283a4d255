#include "covoxslam/backend/pose_graph.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>

#include "covoxslam/backend/rotation_math.h"
#include "covoxslam/core/error.h"

namespace covox {
namespace backend {

Eigen::MatrixXd sqrt_information(const Eigen::MatrixXd& information, const std::string& what) {
  if (!information.allFinite()) throw Error(what + ": the information matrix is not finite");
  const double scale = information.cwiseAbs().maxCoeff();
  if ((information - information.transpose()).cwiseAbs().maxCoeff() > 1e-9 * std::max(scale, 1.0)) {
    throw Error(what + ": the information matrix is not symmetric");
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(
      0.5 * (information + information.transpose()));
  Eigen::VectorXd values = eigen.eigenvalues();
  for (Eigen::Index k = 0; k < values.size(); ++k) {
    // Rounding can push a zero eigenvalue slightly negative; a clearly negative one is an error.
    if (values(k) < -1e-9 * std::max(scale, 1.0)) {
      throw Error(what + ": the information matrix has a negative eigenvalue (" +
                  std::to_string(values(k)) + "); it must be positive semi-definite");
    }
    values(k) = std::sqrt(std::max(values(k), 0.0));
  }
  // S = Lambda^(1/2) V^T gives S^T S = V Lambda V^T.
  return values.asDiagonal() * eigen.eigenvectors().transpose();
}

Se3Pose make_se3_pose(const Eigen::Vector3d& translation, const Eigen::Quaterniond& rotation) {
  const Eigen::Quaterniond q = rotation.normalized();
  Se3Pose pose;
  pose.rotation[0] = q.x();
  pose.rotation[1] = q.y();
  pose.rotation[2] = q.z();
  pose.rotation[3] = q.w();
  for (int k = 0; k < 3; ++k) pose.translation[k] = translation(k);
  return pose;
}

Eigen::Isometry3d to_isometry(const Se3Pose& pose) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() =
      Eigen::Quaterniond(pose.rotation[3], pose.rotation[0], pose.rotation[1], pose.rotation[2])
          .normalized()
          .toRotationMatrix();
  t.translation() = Eigen::Vector3d(pose.translation[0], pose.translation[1], pose.translation[2]);
  return t;
}

namespace {

template <int D>
void store_row_major(const Eigen::MatrixXd& m, double* out) {
  for (int r = 0; r < D; ++r) {
    for (int c = 0; c < D; ++c) out[r * D + c] = m(r, c);
  }
}

std::string constraint_name(int32_t from, int32_t to) {
  return "constraint " + std::to_string(from) + " -> " + std::to_string(to);
}

bool finite_pose(const Se3Pose& p) {
  for (double v : p.rotation) {
    if (!std::isfinite(v)) return false;
  }
  for (double v : p.translation) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}
bool finite_pose(const Pose4Dof& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && std::isfinite(p.yaw);
}

template <class Graph>
void validate_common(const Graph& graph) {
  const int64_t n = static_cast<int64_t>(graph.poses.size());
  if (graph.fixed_vertex != kNoVertex && (graph.fixed_vertex < 0 || graph.fixed_vertex >= n)) {
    throw Error("pose graph: fixed_vertex " + std::to_string(graph.fixed_vertex) +
                " is not a vertex (the graph has " + std::to_string(n) + ")");
  }
  for (int64_t v = 0; v < n; ++v) {
    if (!finite_pose(graph.poses[v]))
      throw Error("pose graph: vertex " + std::to_string(v) + " has a non-finite pose");
  }
  for (size_t k = 0; k < graph.constraints.size(); ++k) {
    const auto& c = graph.constraints[k];
    const int32_t to = constraint_to(c);
    const bool from_ok = c.from >= 0 && c.from < n;
    const bool to_ok = to == kNoVertex || (to >= 0 && to < n);
    if (!from_ok || !to_ok) {
      throw Error("pose graph: constraint " + std::to_string(k) + " (" +
                  constraint_name(c.from, to) + ") names a vertex outside [0, " +
                  std::to_string(n) + ")");
    }
    if (to == c.from)
      throw Error("pose graph: constraint " + std::to_string(k) + " joins vertex " +
                  std::to_string(c.from) + " to itself");
  }
}

}  // namespace

Se3Constraint make_se3_constraint(int32_t from, int32_t to, const Se3Pose& measurement,
                                  const Eigen::Matrix<double, 6, 6>& information) {
  Se3Constraint c;
  c.from = from;
  c.to = to;
  c.measurement = measurement;
  store_row_major<6>(sqrt_information(information, constraint_name(from, to)), c.sqrt_information);
  return c;
}

Pose4Dof inverse_pose_4dof(const Pose4Dof& T) {
  // x_Si = Rz(-yaw) (x_Sj - t).
  const double c = std::cos(T.yaw), s = std::sin(T.yaw);
  Pose4Dof inverse;
  inverse.x = -(c * T.x + s * T.y);
  inverse.y = -(-s * T.x + c * T.y);
  inverse.z = -T.z;
  inverse.yaw = wrap_angle(-T.yaw);
  return inverse;
}

Eigen::Matrix4d inverse_pose_4dof_jacobian(const Pose4Dof& T) {
  // The derivatives of inverse_pose_4dof's four lines.
  const double c = std::cos(T.yaw), s = std::sin(T.yaw);
  const Pose4Dof P = inverse_pose_4dof(T);
  Eigen::Matrix4d A = Eigen::Matrix4d::Zero();
  A(0, 0) = -c;
  A(0, 1) = -s;
  A(0, 3) = P.y;
  A(1, 0) = s;
  A(1, 1) = -c;
  A(1, 3) = -P.x;
  A(2, 2) = -1.0;
  A(3, 3) = -1.0;
  return A;
}

Constraint4Dof make_relative_constraint_4dof(int32_t from, int32_t to, const Pose4Dof& measurement,
                                             const Eigen::Matrix4d& information) {
  Constraint4Dof c;
  c.from = from;
  c.to = to;
  c.kind = Constraint4DofKind::kRelativePose;
  c.measurement = measurement;
  store_row_major<4>(sqrt_information(information, constraint_name(from, to)), c.sqrt_information);
  return c;
}

Constraint4Dof make_position_constraint_4dof(int32_t vertex, const Eigen::Vector3d& position,
                                             const Eigen::Matrix3d& information) {
  Constraint4Dof c;
  c.from = vertex;
  c.to = kNoVertex;
  c.kind = Constraint4DofKind::kAbsolutePosition;
  c.measurement.x = position.x();
  c.measurement.y = position.y();
  c.measurement.z = position.z();
  Eigen::Matrix4d padded = Eigen::Matrix4d::Zero();
  padded.topLeftCorner<3, 3>() = information;
  store_row_major<4>(
      sqrt_information(padded, "position constraint on vertex " + std::to_string(vertex)),
      c.sqrt_information);
  return c;
}

Constraint4Dof make_height_constraint_4dof(int32_t vertex, double height_m, double information_z) {
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();
  information(2, 2) = information_z;
  return make_position_constraint_4dof(vertex, Eigen::Vector3d(0.0, 0.0, height_m), information);
}

void validate_pose_graph(const Se3PoseGraph& graph) { validate_common(graph); }
void validate_pose_graph(const PoseGraph4Dof& graph) { validate_common(graph); }

double pose_graph_cost(const Se3PoseGraph& graph) {
  double cost = 0.0;
  for (const auto& c : graph.constraints) cost += Se3Model::cost(c, graph.poses.data());
  return cost;
}
double pose_graph_cost(const PoseGraph4Dof& graph) {
  double cost = 0.0;
  for (const auto& c : graph.constraints) cost += FourDofModel::cost(c, graph.poses.data());
  return cost;
}

}  // namespace backend
}  // namespace covox

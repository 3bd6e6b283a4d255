#pragma once
// A pose graph on the host: poses, constraints and the gauge. Built by the g2o reader, by the
// submap collection, or by hand; solved by solve_pose_graph() (pose_graph_solver.h).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/backend/pose_graph_models.h"

namespace covox {
namespace backend {

template <class Model>
struct PoseGraph {
  using Pose = typename Model::Pose;
  using Constraint = typename Model::Constraint;

  std::vector<Pose> poses;
  std::vector<Constraint> constraints;
  // Gauge: the vertex held constant (the first submap in voxgraph). kNoVertex holds none, which
  // only makes sense when absolute constraints pin the graph down.
  int32_t fixed_vertex = 0;
};

using Se3PoseGraph = PoseGraph<Se3Model>;
using PoseGraph4Dof = PoseGraph<FourDofModel>;

// S with S^T S = information, for a symmetric positive semi-definite information matrix (a zero
// eigenvalue leaves that direction unconstrained, e.g. a height-only constraint). Throws
// covox::Error naming `what` when the matrix is not finite, not symmetric, or has a negative
// eigenvalue.
Eigen::MatrixXd sqrt_information(const Eigen::MatrixXd& information, const std::string& what);

Se3Pose make_se3_pose(const Eigen::Vector3d& translation, const Eigen::Quaterniond& rotation);
Eigen::Isometry3d to_isometry(const Se3Pose& pose);

Se3Constraint make_se3_constraint(int32_t from, int32_t to, const Se3Pose& measurement,
                                  const Eigen::Matrix<double, 6, 6>& information);

// Odometry or a loop closure: the pose of `to` in the frame of `from` (dx, dy, dz, dyaw) and its
// information over (x, y, z, yaw).
// T^-1 of a 4-DoF pose (x_Si = Rz(-yaw) (x_Sj - t), yaw wrapped into [-pi, pi)) and its 4x4
// Jacobian d T^-1 / d T.
Pose4Dof inverse_pose_4dof(const Pose4Dof& T);
Eigen::Matrix4d inverse_pose_4dof_jacobian(const Pose4Dof& T);

Constraint4Dof make_relative_constraint_4dof(int32_t from, int32_t to, const Pose4Dof& measurement,
                                             const Eigen::Matrix4d& information);
// Absolute position of `vertex` (GNSS), information over (x, y, z).
Constraint4Dof make_position_constraint_4dof(int32_t vertex, const Eigen::Vector3d& position,
                                             const Eigen::Matrix3d& information);
// Height only: z of `vertex` with information `information_z` (1 / sigma^2).
Constraint4Dof make_height_constraint_4dof(int32_t vertex, double height_m, double information_z);

// Throws covox::Error naming the constraint or vertex when an index is out of range, a
// constraint joins a vertex to itself, or a pose is not finite.
void validate_pose_graph(const Se3PoseGraph& graph);
void validate_pose_graph(const PoseGraph4Dof& graph);

// Ceres' convention: 0.5 sum |S r|^2, evaluated on the host (a reference for tests and tools).
double pose_graph_cost(const Se3PoseGraph& graph);
double pose_graph_cost(const PoseGraph4Dof& graph);

}  // namespace backend
}  // namespace covox

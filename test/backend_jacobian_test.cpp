// Analytic Jacobians of the pose-graph residuals against central differences (through the same
// tangent update the solver uses), and CPU/GPU parity of residuals, Jacobians and gradients.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <type_traits>

#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/synthetic_pose_graph.h"
#include "support/test_devices.h"

namespace covox {
namespace backend {
namespace {

Se3Pose random_se3(std::mt19937_64& rng, double max_angle) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
  const double angle = max_angle * std::abs(u(rng));
  return make_se3_pose(Eigen::Vector3d(5 * u(rng), 5 * u(rng), 5 * u(rng)),
                       Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis)));
}

Eigen::Matrix<double, 6, 6> random_information(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Matrix<double, 6, 6> a;
  for (int k = 0; k < 36; ++k) a(k) = u(rng);
  return a * a.transpose() + 0.5 * Eigen::Matrix<double, 6, 6>::Identity();
}

// Largest |analytic - numeric| over both Jacobians of constraint `c`, relative to max(1, |J|).
template <class Model>
double jacobian_error(const typename Model::Constraint& c,
                      std::vector<typename Model::Pose> poses) {
  constexpr int D = Model::kDim;
  double f[D], ji[D * D], jj[D * D];
  Model::evaluate(c, poses.data(), f, ji, jj);
  double worst = 0.0;
  const double h = 1e-6;
  for (int side = 0; side < 2; ++side) {
    const int32_t v = side == 0 ? c.from : constraint_to(c);
    if (v < 0) continue;
    const double* analytic = side == 0 ? ji : jj;
    for (int col = 0; col < D; ++col) {
      double delta[D] = {};
      const auto original = poses[v];
      double plus[D], minus[D], scratch_i[D * D], scratch_j[D * D];
      delta[col] = h;
      poses[v] = Model::plus(original, delta);
      Model::evaluate(c, poses.data(), plus, scratch_i, scratch_j);
      delta[col] = -h;
      poses[v] = Model::plus(original, delta);
      Model::evaluate(c, poses.data(), minus, scratch_i, scratch_j);
      poses[v] = original;
      for (int row = 0; row < D; ++row) {
        const double numeric = (plus[row] - minus[row]) / (2 * h);
        const double a = analytic[row * D + col];
        worst = std::max(worst, std::abs(a - numeric) / std::max(1.0, std::abs(a)));
      }
    }
  }
  return worst;
}

TEST(BackendJacobian, Se3MatchesCentralDifferences) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    // Up to 3 rad of rotation error: exercises the log map far from the identity.
    std::vector<Se3Pose> poses = {random_se3(rng, 3.0), random_se3(rng, 3.0)};
    const Se3Constraint c =
        make_se3_constraint(0, 1, random_se3(rng, 3.0), random_information(rng));
    ASSERT_LT(jacobian_error<Se3Model>(c, poses), 2e-6) << "trial " << trial;
  }
}

TEST(BackendJacobian, Se3AtZeroErrorMatchesCentralDifferences) {
  // The measurement equals the relative pose: the log map sits at its small-angle series.
  std::mt19937_64 rng(3);
  std::vector<Se3Pose> poses = {random_se3(rng, 1.0), random_se3(rng, 1.0)};
  const Eigen::Isometry3d z = to_isometry(poses[0]).inverse() * to_isometry(poses[1]);
  const Se3Constraint c =
      make_se3_constraint(0, 1, make_se3_pose(z.translation(), Eigen::Quaterniond(z.linear())),
                          random_information(rng));
  EXPECT_LT(jacobian_error<Se3Model>(c, poses), 2e-6);
}

TEST(BackendJacobian, FourDofMatchesCentralDifferences) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<Pose4Dof> poses(2);
    for (auto& p : poses) p = Pose4Dof{10 * u(rng), 10 * u(rng), 2 * u(rng), 3.1 * u(rng)};
    Eigen::Matrix4d a;
    for (int k = 0; k < 16; ++k) a(k) = u(rng);
    const Eigen::Matrix4d information = a * a.transpose() + 0.1 * Eigen::Matrix4d::Identity();
    const Pose4Dof z{u(rng), u(rng), u(rng), u(rng)};
    ASSERT_LT(
        jacobian_error<FourDofModel>(make_relative_constraint_4dof(0, 1, z, information), poses),
        1e-6);
    ASSERT_LT(jacobian_error<FourDofModel>(
                  make_position_constraint_4dof(1, Eigen::Vector3d(u(rng), u(rng), u(rng)),
                                                information.topLeftCorner<3, 3>()),
                  poses),
              1e-6);
  }
}

TEST(BackendJacobian, HeightConstraintOnlyConstrainsZ) {
  PoseGraph4Dof graph;
  graph.poses = {Pose4Dof{1.0, 2.0, 3.0, 0.5}};
  graph.fixed_vertex = kNoVertex;
  graph.constraints = {make_height_constraint_4dof(0, 2.0, 4.0)};
  // 0.5 * 4 * (3 - 2)^2 = 2, whatever x, y and yaw are.
  EXPECT_DOUBLE_EQ(pose_graph_cost(graph), 2.0);
}

using testing_support::DeviceTest;
class BackendEvaluationParity : public DeviceTest {};

// The device's evaluation equals the host-side reference evaluation of the models (the CPU run
// checks the assembly; the CUDA run checks the GPU against the same reference).
template <class Graph>
void expect_matches_host_reference(const Graph& graph, Device device) {
  using Model =
      std::conditional_t<std::is_same<Graph, Se3PoseGraph>::value, Se3Model, FourDofModel>;
  constexpr int D = Model::kDim;
  const PoseGraphEvaluation e = evaluate_pose_graph(graph, device);
  ASSERT_EQ(e.residuals.size(), graph.constraints.size() * D);
  std::vector<double> gradient(graph.poses.size() * D, 0.0);
  double cost = 0.0;
  for (size_t k = 0; k < graph.constraints.size(); ++k) {
    const auto& c = graph.constraints[k];
    double f[D], ji[D * D], jj[D * D];
    Model::evaluate(c, graph.poses.data(), f, ji, jj);
    for (int r = 0; r < D; ++r) {
      cost += 0.5 * f[r] * f[r];
      EXPECT_NEAR(e.residuals[k * D + r], f[r], 1e-9 * std::max(1.0, std::abs(f[r])));
    }
    for (int i = 0; i < D * D; ++i) {
      EXPECT_NEAR(e.jacobians_from[k * D * D + i], ji[i], 1e-9 * std::max(1.0, std::abs(ji[i])));
      EXPECT_NEAR(e.jacobians_to[k * D * D + i], jj[i], 1e-9 * std::max(1.0, std::abs(jj[i])));
    }
    const int32_t to = constraint_to(c);
    for (int col = 0; col < D; ++col) {
      for (int row = 0; row < D; ++row) {
        if (c.from != graph.fixed_vertex) gradient[c.from * D + col] += ji[row * D + col] * f[row];
        if (to >= 0 && to != graph.fixed_vertex)
          gradient[to * D + col] += jj[row * D + col] * f[row];
      }
    }
  }
  EXPECT_NEAR(e.cost, cost, 1e-10 * cost);
  for (size_t i = 0; i < gradient.size(); ++i) {
    EXPECT_NEAR(e.gradient[i], gradient[i], 1e-8 * std::max(1.0, std::abs(gradient[i])))
        << "entry " << i;
  }
}

TEST_P(BackendEvaluationParity, Se3MatchesHostReference) {
  SyntheticGraphOptions options;
  options.submaps = 60;
  expect_matches_host_reference(make_synthetic_graph_se3(options).graph, device());
}

TEST_P(BackendEvaluationParity, FourDofMatchesHostReference) {
  SyntheticGraphOptions options;
  options.submaps = 60;
  options.absolute_position_every = 5;
  options.height_constraints = true;
  expect_matches_host_reference(make_synthetic_graph_4dof(options).graph, device());
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(BackendEvaluationParity);

}  // namespace
}  // namespace backend
}  // namespace covox

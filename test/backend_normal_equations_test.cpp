// The block-sparse normal equations against dense J^T J, and the linear solve (PCG with both
// preconditioners) against a dense solve. CPU backend; the CUDA twin is covered by the parity
// tests of the evaluation and of the solution.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "covoxslam/backend/internal/pose_graph_solver_impl.h"
#include "covoxslam/backend/synthetic_pose_graph.h"

namespace covox {
namespace backend {
namespace {

template <class Model>
Eigen::MatrixXd dense_jacobian(const PoseGraph<Model>& graph) {
  constexpr int D = Model::kDim;
  const int64_t n = static_cast<int64_t>(graph.poses.size());
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(graph.constraints.size() * D, n * D);
  for (size_t k = 0; k < graph.constraints.size(); ++k) {
    const auto& c = graph.constraints[k];
    double f[D], ji[D * D], jj[D * D];
    Model::evaluate(c, graph.poses.data(), f, ji, jj);
    for (int r = 0; r < D; ++r) {
      for (int col = 0; col < D; ++col) {
        if (c.from != graph.fixed_vertex) j(k * D + r, c.from * D + col) = ji[r * D + col];
        const int32_t to = constraint_to(c);
        if (to >= 0 && to != graph.fixed_vertex) j(k * D + r, to * D + col) = jj[r * D + col];
      }
    }
  }
  return j;
}

template <class Model>
void check_normal_equations(const PoseGraph<Model>& graph, PcgPreconditioner preconditioner) {
  constexpr int D = Model::kDim;
  const Stream stream(Device::kCpu);
  PoseGraphWorkspace<CpuBackend, Model> w(graph, stream);
  w.evaluate();
  w.assemble();
  const int64_t n = w.unknowns();
  // H column by column through the block-sparse product.
  Eigen::MatrixXd h(n, n);
  std::vector<double> x(n), y(n);
  for (int64_t c = 0; c < n; ++c) {
    std::fill(x.begin(), x.end(), 0.0);
    x[c] = 1.0;
    multiply_normal_matrix<D>(CpuBackend{}, stream, w.view(), w.hessian_diag.data(),
                              w.hessian_off.data(), nullptr, x.data(), y.data());
    for (int64_t r = 0; r < n; ++r) h(r, c) = y[r];
  }
  const Eigen::MatrixXd j = dense_jacobian(graph);
  Eigen::MatrixXd expected = j.transpose() * j;
  const int64_t f = graph.fixed_vertex * D;
  expected.block(f, f, D, D).setIdentity();
  ASSERT_LT((h - expected).cwiseAbs().maxCoeff(), 1e-9 * expected.cwiseAbs().maxCoeff());

  // The damped solve against a dense one.
  PoseGraphSolverOptions options;
  options.preconditioner = preconditioner;
  options.pcg_relative_tolerance = 1e-12;
  options.pcg_max_iterations = 2000;
  const double radius = 1e3;
  const int iterations = w.solve_damped(radius, options);
  const auto damping = w.damping.to_host();
  const auto gradient = w.gradient.to_host();
  const auto step = w.step.to_host();
  Eigen::MatrixXd a = h;
  for (int64_t i = 0; i < n; ++i) a(i, i) += damping[i];
  const Eigen::VectorXd g = Eigen::Map<const Eigen::VectorXd>(gradient.data(), n);
  const Eigen::VectorXd dense = a.ldlt().solve(-g);
  const Eigen::VectorXd ours = Eigen::Map<const Eigen::VectorXd>(step.data(), n);
  EXPECT_LT((ours - dense).norm(), 1e-8 * dense.norm()) << iterations << " PCG iterations";
  std::cout << "  " << to_string(preconditioner) << ": " << iterations << " PCG iterations for "
            << n << " unknowns\n";
}

TEST(BackendNormalEquations, Se3MatchesDenseWithBothPreconditioners) {
  SyntheticGraphOptions options;
  options.submaps = 90;
  const auto problem = make_synthetic_graph_se3(options);
  check_normal_equations(problem.graph, PcgPreconditioner::kBlockJacobi);
  check_normal_equations(problem.graph, PcgPreconditioner::kOdometryChain);
}

TEST(BackendNormalEquations, FourDofMatchesDenseWithBothPreconditioners) {
  SyntheticGraphOptions options;
  options.submaps = 90;
  options.absolute_position_every = 7;
  options.height_constraints = true;
  auto problem = make_synthetic_graph_4dof(options);
  problem.graph.fixed_vertex = 30;  // a gauge in the middle of the chain
  check_normal_equations(problem.graph, PcgPreconditioner::kBlockJacobi);
  check_normal_equations(problem.graph, PcgPreconditioner::kOdometryChain);
}

}  // namespace
}  // namespace backend
}  // namespace covox

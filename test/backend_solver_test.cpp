// The LM + PCG pose-graph solver: synthetic 4-DoF and SE(3) graphs with known truth (solution
// near the truth, final cost equal to Ceres' on the same residuals), parking-garage.g2o against
// Ceres, the gauge, and CPU/GPU parity of the solution.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include "covoxslam/backend/ceres_pose_graph_oracle.h"
#include "covoxslam/backend/g2o_reader.h"
#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/synthetic_pose_graph.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"
#include "support/solver_test_options.h"
#include "support/test_devices.h"

namespace covox {
namespace backend {
namespace {

using testing_support::DeviceTest;

using testing_support::relative_difference;

// The comparisons with Ceres are about the optimum, not about stopping early.
PoseGraphSolverOptions tight_options() {
  return testing_support::tight_solver_options(1e-10, 1000);
}

#if COVOX_HAVE_CERES
// Solves `copy` (the same graph as the one `summary` reports on, still at its initial poses) with
// Ceres: the initial costs must agree to rounding, as both evaluate the same residuals, and the
// final costs within `final_tolerance`, as both should reach the same optimum.
template <class Graph>
void expect_costs_match_ceres(const PoseGraphSolverSummary& summary, Graph* copy,
                              double final_tolerance) {
  const auto oracle = ceres_oracle::solve(copy);
  SCOPED_TRACE("ceres: " + oracle.brief_report);
  ASSERT_TRUE(oracle.usable);
  EXPECT_LT(relative_difference(summary.initial_cost, oracle.initial_cost), 1e-12);
  EXPECT_LT(relative_difference(summary.final_cost, oracle.final_cost), final_tolerance)
      << "ours " << summary.final_cost << ", Ceres " << oracle.final_cost;
}
#endif

// Root mean square position error against the truth and the largest heading error.
double position_rmse(const std::vector<Pose4Dof>& a, const std::vector<Pose4Dof>& b,
                     double* max_yaw_error) {
  double sum = 0.0;
  *max_yaw_error = 0.0;
  for (size_t k = 0; k < a.size(); ++k) {
    sum +=
        std::pow(a[k].x - b[k].x, 2) + std::pow(a[k].y - b[k].y, 2) + std::pow(a[k].z - b[k].z, 2);
    *max_yaw_error = std::max(*max_yaw_error, std::abs(wrap_angle(a[k].yaw - b[k].yaw)));
  }
  return std::sqrt(sum / a.size());
}

double position_rmse(const std::vector<Se3Pose>& a, const std::vector<Se3Pose>& b,
                     double* max_angle_error) {
  double sum = 0.0;
  *max_angle_error = 0.0;
  for (size_t k = 0; k < a.size(); ++k) {
    const Eigen::Isometry3d ta = to_isometry(a[k]), tb = to_isometry(b[k]);
    sum += (ta.translation() - tb.translation()).squaredNorm();
    *max_angle_error = std::max(*max_angle_error,
                                Eigen::AngleAxisd(ta.linear().transpose() * tb.linear()).angle());
  }
  return std::sqrt(sum / a.size());
}

class BackendSolver : public DeviceTest {};

TEST_P(BackendSolver, FourDofSyntheticGraphReachesTheTruth) {
  SyntheticGraphOptions options;
  options.submaps = 120;
  options.absolute_position_every = 10;
  options.height_constraints = true;
  Synthetic4DofGraph problem = make_synthetic_graph_4dof(options);
  double yaw_before = 0.0;
  const double rmse_before = position_rmse(problem.graph.poses, problem.truth, &yaw_before);
  const auto summary = solve_pose_graph(&problem.graph, device(), tight_options());
  SCOPED_TRACE(summary.report());
  EXPECT_TRUE(summary.converged());
  EXPECT_LT(summary.final_cost, summary.initial_cost);
  double yaw_after = 0.0;
  const double rmse_after = position_rmse(problem.graph.poses, problem.truth, &yaw_after);
  // Measurements have 5 cm / 0.01 rad noise; the initial guess is off by up to 0.5 m / 0.05 rad.
  EXPECT_LT(rmse_after, 0.1) << "before: " << rmse_before;
  EXPECT_LT(yaw_after, 0.04) << "before: " << yaw_before;
  // The reported cost is the cost of the returned poses.
  EXPECT_NEAR(summary.final_cost, pose_graph_cost(problem.graph), 1e-9 * summary.final_cost);
}

TEST_P(BackendSolver, Se3SyntheticGraphReachesTheTruth) {
  SyntheticGraphOptions options;
  options.submaps = 120;
  SyntheticSe3Graph problem = make_synthetic_graph_se3(options);
  const auto summary = solve_pose_graph(&problem.graph, device(), tight_options());
  SCOPED_TRACE(summary.report());
  EXPECT_TRUE(summary.converged());
  double angle_after = 0.0;
  const double rmse_after = position_rmse(problem.graph.poses, problem.truth, &angle_after);
  EXPECT_LT(rmse_after, 0.15);
  EXPECT_LT(angle_after, 0.06);
  EXPECT_NEAR(summary.final_cost, pose_graph_cost(problem.graph), 1e-9 * summary.final_cost);
}

TEST_P(BackendSolver, FixedVertexDoesNotMove) {
  SyntheticGraphOptions options;
  options.submaps = 40;
  Synthetic4DofGraph problem = make_synthetic_graph_4dof(options);
  problem.graph.fixed_vertex = 17;
  const Pose4Dof before = problem.graph.poses[17];
  solve_pose_graph(&problem.graph, device(), tight_options());
  EXPECT_EQ(problem.graph.poses[17].x, before.x);
  EXPECT_EQ(problem.graph.poses[17].y, before.y);
  EXPECT_EQ(problem.graph.poses[17].z, before.z);
  EXPECT_EQ(problem.graph.poses[17].yaw, before.yaw);
}

// CG runs in rounds of enqueued iterations and reads its state back once per round: the
// iteration cap is kept exactly, and iterations enqueued after CG has stopped change nothing
// (a solve capped at the iteration where CG stopped returns the same poses, bit for bit).
TEST_P(BackendSolver, ConjugateGradientsStopWhereTheyWouldStopIterationByIteration) {
  SyntheticGraphOptions graph_options;
  graph_options.submaps = 60;
  const Synthetic4DofGraph problem = make_synthetic_graph_4dof(graph_options);
  PoseGraphSolverOptions options;
  options.max_iterations = 1;  // one LM step: one CG solve
  auto solve = [&](int pcg_max_iterations, double tolerance) {
    PoseGraph4Dof graph = problem.graph;
    options.pcg_max_iterations = pcg_max_iterations;
    options.pcg_relative_tolerance = tolerance;
    const PoseGraphSolverSummary summary = solve_pose_graph(&graph, device(), options);
    return std::make_pair(summary, graph.poses);
  };
  for (int cap : {1, 5, 13}) {
    EXPECT_EQ(solve(cap, 1e-14).first.pcg_iterations, cap) << "cap " << cap;
  }
  const auto free_run = solve(500, 0.1);
  const int stopped_at = static_cast<int>(free_run.first.pcg_iterations);
  ASSERT_GT(stopped_at, 1);
  ASSERT_LT(stopped_at, 500);
  const auto capped = solve(stopped_at, 0.1);
  EXPECT_EQ(capped.first.pcg_iterations, stopped_at);
  ASSERT_EQ(capped.second.size(), free_run.second.size());
  bool one_short_differs = false;
  const auto one_short = solve(stopped_at - 1, 0.1);
  for (size_t k = 0; k < free_run.second.size(); ++k) {
    EXPECT_EQ(capped.second[k].x, free_run.second[k].x) << "vertex " << k;
    EXPECT_EQ(capped.second[k].yaw, free_run.second[k].yaw) << "vertex " << k;
    one_short_differs = one_short_differs || one_short.second[k].x != free_run.second[k].x;
  }
  EXPECT_TRUE(one_short_differs) << "the last iteration must have moved the step";
}

TEST_P(BackendSolver, InvalidGraphIsAClearError) {
  PoseGraph4Dof graph;
  graph.poses.resize(2);
  graph.constraints = {
      make_relative_constraint_4dof(0, 5, Pose4Dof{}, Eigen::Matrix4d::Identity())};
  try {
    solve_pose_graph(&graph, device());
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what())
                  .find("constraint 0 (constraint 0 -> 5) names a vertex outside [0, 2)"),
              std::string::npos)
        << error.what();
  }
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(BackendSolver);

TEST(BackendSolverParity, CpuAndCudaSolutionsAgree) {
  COVOX_SKIP_WITHOUT_GPU();
  SyntheticGraphOptions options;
  options.submaps = 200;
  SyntheticSe3Graph cpu = make_synthetic_graph_se3(options);
  SyntheticSe3Graph cuda = make_synthetic_graph_se3(options);
  const auto cpu_summary = solve_pose_graph(&cpu.graph, Device::kCpu, tight_options());
  const auto cuda_summary = solve_pose_graph(&cuda.graph, Device::kCuda, tight_options());
  EXPECT_NEAR(cpu_summary.final_cost, cuda_summary.final_cost, 1e-8 * cpu_summary.final_cost);
  double angle = 0.0;
  EXPECT_LT(position_rmse(cpu.graph.poses, cuda.graph.poses, &angle), 1e-6);
  EXPECT_LT(angle, 1e-6);
}

#if COVOX_HAVE_CERES
TEST(BackendSolverCeres, FourDofFinalCostEqualsCeres) {
  SyntheticGraphOptions options;
  options.submaps = 150;
  options.absolute_position_every = 10;
  options.height_constraints = true;
  Synthetic4DofGraph ours = make_synthetic_graph_4dof(options);
  Synthetic4DofGraph theirs = make_synthetic_graph_4dof(options);
  const auto summary = solve_pose_graph(&ours.graph, Device::kCpu, tight_options());
  SCOPED_TRACE(summary.report());
  expect_costs_match_ceres(summary, &theirs.graph, 1e-6);
}

TEST(BackendSolverCeres, Se3FinalCostEqualsCeres) {
  SyntheticGraphOptions options;
  options.submaps = 150;
  SyntheticSe3Graph ours = make_synthetic_graph_se3(options);
  SyntheticSe3Graph theirs = make_synthetic_graph_se3(options);
  const auto summary = solve_pose_graph(&ours.graph, Device::kCpu, tight_options());
  SCOPED_TRACE(summary.report());
  expect_costs_match_ceres(summary, &theirs.graph, 1e-6);
}
#endif

class BackendParkingGarage : public DeviceTest {
 protected:
  std::string path() const { return io::data_directory() + "/pose-graphs/parking-garage.g2o"; }

  // Solves the file with `options` and compares the final cost with Ceres' (tight tolerances,
  // sparse Cholesky: the reference optimum).
  void compare_with_ceres(const PoseGraphSolverOptions& options, double relative_tolerance) {
    if (!std::filesystem::exists(path()))
      GTEST_SKIP() << "missing " << path() << " (set COVOX_DATA_DIR)";
    G2oGraph ours = read_g2o(path());
    ASSERT_EQ(ours.graph.poses.size(), 1661u);
    ASSERT_EQ(ours.graph.constraints.size(), 6275u);
    const auto summary = solve_pose_graph(&ours.graph, device(), options);
    SCOPED_TRACE(summary.report());
    std::cout << "  " << summary.report() << "\n";
    EXPECT_LT(summary.final_cost, summary.initial_cost);
#if COVOX_HAVE_CERES
    G2oGraph theirs = read_g2o(path());
    expect_costs_match_ceres(summary, &theirs.graph, relative_tolerance);
#else
    (void)relative_tolerance;
    GTEST_SKIP() << "Ceres not found at configure time: solved (" << summary.report()
                 << ") but not compared with the oracle";
#endif
  }
};

// The default solver settings (inexact PCG steps, relative decrease 1e-6) in a few seconds. On
// this long, loosely stiff trajectory CG cannot solve each step exactly within its iteration cap,
// so LM stops a little above the optimum: within 1e-3 of Ceres.
TEST_P(BackendParkingGarage, DefaultSettingsComeCloseToCeres) {
  PoseGraphSolverOptions options;
  options.preconditioner = PcgPreconditioner::kOdometryChain;
  compare_with_ceres(options, 1e-3);
}

// The target, 1e-4 of Ceres' final cost: needs ~200 LM iterations of up to 2000 PCG
// iterations each (about 150 s on 2 CPU cores), so it runs only with COVOX_SLOW_TESTS=1.
TEST_P(BackendParkingGarage, TightSettingsMatchCeresWithin1e4) {
  if (std::getenv("COVOX_SLOW_TESTS") == nullptr) {
    GTEST_SKIP() << "slow (minutes on a CPU): set COVOX_SLOW_TESTS=1 to run";
  }
  PoseGraphSolverOptions options = tight_options();
  options.function_tolerance = 1e-9;
  options.pcg_relative_tolerance = 1e-6;
  options.pcg_max_iterations = 2000;
  options.preconditioner = PcgPreconditioner::kOdometryChain;
  compare_with_ceres(options, 1e-4);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(BackendParkingGarage);

}  // namespace
}  // namespace backend
}  // namespace covox

#pragma once
// Ceres as an independent oracle for the pose-graph solver, used ONLY by tests and benchmarks
// (target covox_ceres_oracle; the library never links Ceres). Header-only and empty unless
// COVOX_HAVE_CERES is 1, so callers guard their use with `#if COVOX_HAVE_CERES`.
//
// The residuals are the definitions of pose_graph_models.h re-written with Ceres' own types
// (Eigen quaternions over Jets, ceres::QuaternionToAngleAxis) and differentiated automatically,
// so neither the analytic Jacobians nor the LM/PCG code of covoxslam are involved.
#if COVOX_HAVE_CERES
#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Geometry>
#include <chrono>
#include <string>

#include "covoxslam/backend/pose_graph.h"

namespace covox {
namespace backend {
namespace ceres_oracle {

struct Se3Residual {
  explicit Se3Residual(const Se3Constraint& c) : constraint(c) {}
  template <class T>
  bool operator()(const T* q_i, const T* t_i, const T* q_j, const T* t_j, T* out) const {
    const Eigen::Map<const Eigen::Quaternion<T>> qi(q_i), qj(q_j);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> ti(t_i), tj(t_j);
    const double* zq = constraint.measurement.rotation;
    const Eigen::Quaternion<T> qz{T{zq[3]}, T{zq[0]}, T{zq[1]}, T{zq[2]}};
    const Eigen::Matrix<T, 3, 1> tz(T(constraint.measurement.translation[0]),
                                    T(constraint.measurement.translation[1]),
                                    T(constraint.measurement.translation[2]));
    const Eigen::Quaternion<T> qe = qz.conjugate() * qi.conjugate() * qj;
    T r[6];
    const Eigen::Matrix<T, 3, 1> te = qz.conjugate() * (qi.conjugate() * (tj - ti) - tz);
    const T wxyz[4] = {qe.w(), qe.x(), qe.y(), qe.z()};
    ceres::QuaternionToAngleAxis(wxyz, r + 3);
    for (int k = 0; k < 3; ++k) r[k] = te(k);
    for (int row = 0; row < 6; ++row) {
      out[row] = T(0.0);
      for (int col = 0; col < 6; ++col)
        out[row] += T(constraint.sqrt_information[row * 6 + col]) * r[col];
    }
    return true;
  }
  Se3Constraint constraint;
};

template <class T>
T wrap_angle_jet(const T& angle) {
  using std::floor;
  constexpr double kTwoPi = 6.283185307179586476925286766559;
  constexpr double kPi = 3.1415926535897932384626433832795;
  return angle - T(kTwoPi) * floor((angle + T(kPi)) / T(kTwoPi));
}

// Pose blocks are (x, y, z, yaw).
struct Relative4DofResidual {
  explicit Relative4DofResidual(const Constraint4Dof& c) : constraint(c) {}
  template <class T>
  bool operator()(const T* pi, const T* pj, T* out) const {
    using std::cos;
    using std::sin;
    const T c = cos(pi[3]), s = sin(pi[3]);
    const T dx = pj[0] - pi[0], dy = pj[1] - pi[1];
    const Pose4Dof& z = constraint.measurement;
    const T r[4] = {c * dx + s * dy - T(z.x), -s * dx + c * dy - T(z.y), pj[2] - pi[2] - T(z.z),
                    wrap_angle_jet(pj[3] - pi[3] - T(z.yaw))};
    whiten(r, out);
    return true;
  }
  template <class T>
  void whiten(const T* r, T* out) const {
    for (int row = 0; row < 4; ++row) {
      out[row] = T(0.0);
      for (int col = 0; col < 4; ++col)
        out[row] += T(constraint.sqrt_information[row * 4 + col]) * r[col];
    }
  }
  Constraint4Dof constraint;
};

struct Absolute4DofResidual {
  explicit Absolute4DofResidual(const Constraint4Dof& c) : relative(c) {}
  template <class T>
  bool operator()(const T* p, T* out) const {
    const Pose4Dof& z = relative.constraint.measurement;
    const T r[4] = {p[0] - T(z.x), p[1] - T(z.y), p[2] - T(z.z), T(0.0)};
    relative.whiten(r, out);
    return true;
  }
  Relative4DofResidual relative;
};

struct OracleOptions {
  ceres::LinearSolverType linear_solver = ceres::SPARSE_NORMAL_CHOLESKY;
  int threads = 1;
  int max_iterations = 200;
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  double max_solver_time_s = 1e9;  // Ceres' own wall-clock limit (benchmarks bound long runs)
};

struct OracleResult {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double solve_time_s = 0.0;  // building the problem and solving
  int iterations = 0;
  bool usable = false;
  std::string brief_report;
};

inline ceres::Solver::Options solver_options(const OracleOptions& o) {
  ceres::Solver::Options options;
  options.linear_solver_type = o.linear_solver;
  options.num_threads = o.threads;
  options.max_num_iterations = o.max_iterations;
  options.function_tolerance = o.function_tolerance;
  options.gradient_tolerance = o.gradient_tolerance;
  options.parameter_tolerance = o.parameter_tolerance;
  options.max_solver_time_in_seconds = o.max_solver_time_s;
  options.minimizer_progress_to_stdout = false;
  return options;
}

inline OracleResult finish(ceres::Problem* problem, const OracleOptions& o,
                           std::chrono::steady_clock::time_point start) {
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options(o), problem, &summary);
  OracleResult result;
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = static_cast<int>(summary.iterations.size());
  result.usable = summary.IsSolutionUsable();
  result.brief_report = summary.BriefReport();
  result.solve_time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

// Solves `graph` in place with Ceres.
inline OracleResult solve(Se3PoseGraph* graph, const OracleOptions& o = OracleOptions()) {
  const auto start = std::chrono::steady_clock::now();
  ceres::Problem problem;
  for (const Se3Constraint& c : graph->constraints) {
    Se3Pose& pi = graph->poses[c.from];
    Se3Pose& pj = graph->poses[c.to];
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<Se3Residual, 6, 4, 3, 4, 3>(new Se3Residual(c)), nullptr,
        pi.rotation, pi.translation, pj.rotation, pj.translation);
  }
  for (Se3Pose& p : graph->poses) {
    if (problem.HasParameterBlock(p.rotation))
      problem.SetManifold(p.rotation, new ceres::EigenQuaternionManifold);
  }
  if (graph->fixed_vertex >= 0) {
    Se3Pose& fixed = graph->poses[graph->fixed_vertex];
    if (problem.HasParameterBlock(fixed.rotation))
      problem.SetParameterBlockConstant(fixed.rotation);
    if (problem.HasParameterBlock(fixed.translation))
      problem.SetParameterBlockConstant(fixed.translation);
  }
  return finish(&problem, o, start);
}

// The constraints of a 4-DoF graph as residual blocks over its poses (x, y, z, yaw) in place.
inline void add_constraints_4dof(PoseGraph4Dof* graph, ceres::Problem* problem_pointer) {
  static_assert(sizeof(Pose4Dof) == 4 * sizeof(double), "Pose4Dof must be four packed doubles");
  ceres::Problem& problem = *problem_pointer;
  for (const Constraint4Dof& c : graph->constraints) {
    double* pi = &graph->poses[c.from].x;
    if (c.kind == Constraint4DofKind::kAbsolutePosition) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<Absolute4DofResidual, 4, 4>(new Absolute4DofResidual(c)),
          nullptr, pi);
    } else {
      double* pj = &graph->poses[c.to].x;
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Relative4DofResidual, 4, 4, 4>(
                                   new Relative4DofResidual(c)),
                               nullptr, pi, pj);
    }
  }
}

inline void hold_fixed_vertex_4dof(PoseGraph4Dof* graph, ceres::Problem* problem) {
  if (graph->fixed_vertex >= 0 &&
      problem->HasParameterBlock(&graph->poses[graph->fixed_vertex].x)) {
    problem->SetParameterBlockConstant(&graph->poses[graph->fixed_vertex].x);
  }
}

inline OracleResult solve(PoseGraph4Dof* graph, const OracleOptions& o = OracleOptions()) {
  const auto start = std::chrono::steady_clock::now();
  ceres::Problem problem;
  add_constraints_4dof(graph, &problem);
  hold_fixed_vertex_4dof(graph, &problem);
  return finish(&problem, o, start);
}

}  // namespace ceres_oracle
}  // namespace backend
}  // namespace covox
#endif  // COVOX_HAVE_CERES

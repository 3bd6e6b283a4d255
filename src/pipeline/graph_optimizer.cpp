#include "covoxslam/pipeline/graph_optimizer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>

#include "covoxslam/core/log.h"
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegPerRad = 180.0 / kPi;

double square_ratio(double value, double bound) { return (value / bound) * (value / bound); }

}  // namespace

// One optimisation: the graph, what is left of the budget, and the report. Every solve goes
// through solve(), which refuses once the budget is spent; a refused or failed solve ends the
// optimisation with the latest applied solution kept.
class GraphOptimizer::Run {
 public:
  Run(const GraphOptimizer& policy, OptimizedGraph& graph, int64_t budget)
      : policy_(policy), graph_(graph) {
    report_.budget = budget;
  }

  OptimizationReport gated_optimization() {
    if (!(policy_.max_residual_m_ > 0.0)) {
      if (solve_robust()) estimate_odometry_noise();
      return report_;
    }
    // The consistency gate: every optimisation starts from all registration constraints, so one
    // set aside before comes back when the graph has come to agree with it.
    graph_.edit([](SubmapPoseGraph& graph) {
      const std::vector<SubmapConstraint>& constraints = graph.constraints();
      for (size_t k = 0; k < constraints.size(); ++k) {
        if (constraints[k].kind == SubmapConstraintKind::kRegistration) graph.set_active(k, true);
      }
    });
    // Each round sets aside at least one constraint, so the rounds end; the cap bounds the time.
    // Worst-first rounds (gate.worst_fraction) set aside fewer per round, so they get more.
    const int max_rounds = policy_.worst_fraction_ > 0.0 ? 25 : 10;
    int64_t set_aside = 0;
    for (int round = 0; round < max_rounds; ++round) {
      if (!solve_robust()) return report_;
      int now = 0;
      graph_.edit([&](SubmapPoseGraph& graph) {
        now = set_aside_inconsistent_registrations(&graph, policy_.max_residual_m_,
                                                   policy_.worst_fraction_);
      });
      set_aside += now;
      if (now == 0) break;
      if (round + 1 == max_rounds) solve_robust();  // without the last ones set aside
    }
    estimate_odometry_noise();
    report_.gate_finished = true;
    report_.set_aside = set_aside;
    return report_;
  }

 private:
  // One solve of the graph as it is. Absolute constraints are linearised at the current yaw
  // (their lever arm, see submap_pose_graph.h): re-solved a few times while the yaw still moves.
  bool solve() {
    const int passes = 5;
    for (int pass = 0; pass < passes; ++pass) {
      if (report_.solves >= report_.budget) {
        report_.budget_exhausted = true;
        return false;
      }
      OptimizedGraph::SolverInput input;
      try {
        input = graph_.solver_input();
      } catch (const std::exception& error) {
        ++report_.failed_solves;
        log_error("SLAM backend: building the pose graph failed: ", error.what());
        return false;
      }
      if (input.graph.graph.poses.size() < 2) return true;  // one (fixed) vertex: nothing to solve
      const std::vector<backend::Pose4Dof> before = input.graph.graph.poses;
      const auto start = std::chrono::steady_clock::now();
      backend::PoseGraphSolverSummary summary;
      try {
        summary = input.terms.empty() ? backend::solve_pose_graph(&input.graph.graph,
                                                                  policy_.device_, policy_.solver_)
                                      : backend::solve_pose_graph(&input.graph.graph, input.terms,
                                                                  policy_.device_, policy_.solver_);
      } catch (const std::exception& error) {
        ++report_.failed_solves;
        log_error("SLAM backend: pose-graph optimisation failed: ", error.what());
        return false;
      }
      const std::chrono::duration<double> solve_s = std::chrono::steady_clock::now() - start;
      log_message(LogLevel::kDebug, "SLAM backend: ", input.graph.graph.poses.size(), " submaps, ",
                  input.graph.graph.constraints.size(), " constraints: ", summary.report());
      graph_.apply(input.graph, summary, solve_s.count());
      ++report_.solves;
      double max_yaw_change = 0.0;
      for (size_t k = 0; k < before.size(); ++k) {
        const double change =
            std::remainder(input.graph.graph.poses[k].yaw - before[k].yaw, 2.0 * kPi);
        max_yaw_change = std::max(max_yaw_change, std::abs(change));
      }
      if (!input.has_absolute || max_yaw_change < 1e-6) break;
    }
    return true;
  }

  // solve() under the robust loss on registration constraints, if any: iteratively reweighted
  // least squares, each solve's weights from the previous solution, starting from the plain
  // least-squares one; a few rounds settle the weights.
  bool solve_robust() {
    const double scale = policy_.loss_scale_sigmas_;
    if (!(scale > 0.0)) return solve();
    graph_.edit([](SubmapPoseGraph& graph) {
      for (size_t k = 0; k < graph.constraints().size(); ++k) graph.set_weight(k, 1.0);
    });
    const int max_rounds = 8;
    for (int round = 0; round < max_rounds; ++round) {
      if (!solve()) return false;
      double change = 0.0;
      graph_.edit(
          [&](SubmapPoseGraph& graph) { change = reweight_registrations_cauchy(&graph, scale); });
      if (change < 0.01) break;
    }
    return solve();
  }

  RevisitDrift revisit_drift() {
    if (!(policy_.revisit_min_path_m_ > 0.0)) return RevisitDrift();
    const std::vector<double> path_at_node_m = graph_.path_at_node_m();
    RevisitDrift drift;
    graph_.edit([&](SubmapPoseGraph& graph) {
      drift = estimate_revisit_drift(graph, path_at_node_m, policy_.revisit_min_path_m_);
    });
    return drift;
  }

  // Variance-component estimation of the odometry's noise after a solve, re-solving until the
  // factors settle (false when a solve failed or the budget ran out; true at once when off).
  bool estimate_odometry_noise() {
    const GraphOptimizer& p = policy_;
    // The configured drift bounds the estimate from above: without it there is nothing to
    // estimate.
    if (!p.estimate_noise_ || !(p.drift_m_per_m_ > 0.0) || !(p.drift_deg_per_m_ > 0.0)) return true;
    const double floor_m = std::min(1.0, p.min_drift_m_per_m_ / p.drift_m_per_m_);
    const double floor_deg = std::min(1.0, p.min_drift_deg_per_m_ / p.drift_deg_per_m_);
    const auto bounded = [](double value, double low) {
      return std::min(1.0, std::max(low, value));
    };
    // The revisits' drift raises the floors: the estimate may not claim an odometry better than
    // what its own revisits show.
    const RevisitDrift revisits = revisit_drift();
    const double floor_t =
        std::max(floor_m * floor_m, square_ratio(revisits.m_per_m, p.drift_m_per_m_));
    const double floor_yaw = std::max(
        floor_deg * floor_deg, square_ratio(revisits.rad_per_m * kDegPerRad, p.drift_deg_per_m_));
    // Each round scales the odometry's factors by the residuals' ratios at the latest solution
    // and solves again; the ratios tend to 1 as the factors settle. The bounds keep the factors
    // where the configuration says the odometry can be.
    const int max_rounds = 10;
    for (int round = 0; round < max_rounds; ++round) {
      bool settled = true;
      graph_.edit([&](SubmapPoseGraph& graph) {
        const VarianceRatios ratios = estimate_variance_ratios(graph);
        const VarianceFactors old = graph.variance_factors(SubmapConstraintKind::kOdometry);
        const VarianceFactors factors{
            bounded(old.translation * ratios.odometry.translation, floor_t),
            bounded(old.yaw * ratios.odometry.yaw, floor_yaw)};
        graph.set_variance_factors(SubmapConstraintKind::kOdometry, factors);
        log_message(LogLevel::kDebug, "SLAM backend: odometry variance factors ",
                    factors.translation, " ", factors.yaw, " (redundancy ",
                    ratios.odometry_redundancy.translation, " ", ratios.odometry_redundancy.yaw,
                    "; registration ratios ", ratios.registration.translation, " ",
                    ratios.registration.yaw, "; revisits ", revisits.revisits, " showing ",
                    revisits.m_per_m * 100.0, " % and ", revisits.rad_per_m * kDegPerRad,
                    " deg/m)");
        report_.noise_estimated = true;
        report_.odometry_drift_m_per_m = p.drift_m_per_m_ * std::sqrt(factors.translation);
        report_.odometry_drift_deg_per_m = p.drift_deg_per_m_ * std::sqrt(factors.yaw);
        report_.revisits = revisits;
        // Standard deviations within 2 % of the last ones: the solution would barely move.
        settled = std::abs(std::log(factors.translation / old.translation)) < 0.04 &&
                  std::abs(std::log(factors.yaw / old.yaw)) < 0.04;
      });
      if (settled) break;
      if (!solve_robust()) return false;
    }
    return true;
  }

  const GraphOptimizer& policy_;
  OptimizedGraph& graph_;
  OptimizationReport report_;
};

GraphOptimizer::GraphOptimizer(const SlamConfig& config)
    : max_residual_m_(config.registration.gate.max_residual_vox * config.map.voxel_size_m),
      worst_fraction_(config.registration.gate.worst_fraction),
      loss_scale_sigmas_(config.registration_loss_scale_sigmas),
      estimate_noise_(config.estimate_odometry_noise),
      drift_m_per_m_(config.odometry_drift_m_per_m),
      drift_deg_per_m_(config.odometry_drift_deg_per_m),
      min_drift_m_per_m_(config.min_odometry_drift_m_per_m),
      min_drift_deg_per_m_(config.min_odometry_drift_deg_per_m),
      revisit_min_path_m_(config.revisit_drift_min_path_m),
      solves_per_new_submap_(config.max_solves_per_new_submap),
      device_(config.device),
      solver_(config.solver) {}

OptimizationReport GraphOptimizer::optimize(OptimizedGraph& graph, int64_t new_submaps) {
  const int64_t budget = solves_per_new_submap_ * std::max<int64_t>(1, new_submaps);
  Run run(*this, graph, budget);
  const OptimizationReport report = run.gated_optimization();
  log_message(LogLevel::kDebug, "SLAM backend: optimisation of ", new_submaps,
              " new submaps: ", report.solves, " solves of a budget of ", budget);
  if (report.budget_exhausted) {
    log_message(LogLevel::kInfo, "SLAM backend: the optimisation stopped at its budget of ",
                report.budget, " solves (pose_graph.max_solves_per_new_submap x ",
                std::max<int64_t>(1, new_submaps), " new submaps); the latest solution is kept");
  }
  return report;
}

}  // namespace pipeline
}  // namespace covox

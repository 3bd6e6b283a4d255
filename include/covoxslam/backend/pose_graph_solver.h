#pragma once
// Levenberg-Marquardt for pose graphs on the CPU or the GPU (one source, see
// pose_graph_solver_impl.h):
//  * residuals and analytic Jacobians of all constraints evaluated in parallel into buffers that
//    are allocated once per solve on the device;
//  * block-sparse normal equations (D x D blocks) assembled in parallel without atomics;
//  * the damped system solved with conjugate gradients, block-Jacobi preconditioned;
//  * trust-region damping updated as in Ceres (Nielsen's rule): on success
//    radius /= max(1/3, 1 - (2 rho - 1)^3), on failure radius /= v, v *= 2.
// Cost convention: 0.5 sum |S r|^2, as Ceres reports it.
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/registration_terms.h"
#include "covoxslam/core/device.h"

namespace covox {
namespace backend {

enum class PcgPreconditioner {
  kBlockJacobi,    // inverse of each damped diagonal block (fully parallel)
  kOdometryChain,  // block-tridiagonal part of H in vertex order, solved exactly (a sequential
                   // sweep): far fewer CG iterations on long trajectories
};
const char* to_string(PcgPreconditioner preconditioner);

struct PoseGraphSolverOptions {
  int max_iterations = 100;
  // Stop when an accepted step lowers the cost by less than this fraction (Ceres' default 1e-6).
  double function_tolerance = 1e-6;
  // Stop when max |gradient| falls below this.
  double gradient_tolerance = 1e-10;
  // Stop when |step| <= parameter_tolerance * (|x| + parameter_tolerance).
  double parameter_tolerance = 1e-8;
  double initial_trust_region_radius = 1e4;
  double max_trust_region_radius = 1e16;
  double min_trust_region_radius = 1e-32;
  double min_relative_decrease = 1e-3;  // accept a step when actual / predicted decrease > this
  double min_diagonal = 1e-6;           // clamp of diag(H) used for damping
  double max_diagonal = 1e32;
  int pcg_max_iterations = 500;
  // |b - A x| <= tol * |b|. An inexact LM step (Ceres' inexact-Newton forcing term eta = 0.1):
  // far from the minimum an exact step is wasted work, since the next linearisation replaces
  // it, and LM's acceptance test still guards the cost.
  double pcg_relative_tolerance = 1e-1;
  // The chain is the default: submap graphs are long odometry chains, whose coupling along the
  // chain block-Jacobi ignores and the chain preconditioner inverts, so CG needs fewer iterations.
  PcgPreconditioner preconditioner = PcgPreconditioner::kOdometryChain;
  // kOdometryChain: the chain is cut into segments of this many consecutive vertices, one device
  // thread each (0: one segment, the exact chain). Shorter segments sweep in parallel but hold less
  // of the chain; the same value on both backends keeps their iterates alike.
  int chain_segment_vertices = 8;
};

enum class PoseGraphTermination {
  kFunctionTolerance,
  kGradientTolerance,
  kParameterTolerance,
  kMaxIterations,
  kTrustRegionCollapsed,
  kNoConstraints
};
const char* to_string(PoseGraphTermination termination);

struct PoseGraphSolverSummary {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;  // LM iterations (linear solves)
  int accepted_steps = 0;
  int64_t pcg_iterations = 0;  // summed over all LM iterations
  PoseGraphTermination termination = PoseGraphTermination::kMaxIterations;
  double solve_time_s = 0.0;             // upload, solve and download
  int64_t registration_points = 0;       // points of all registration terms
  int64_t registration_points_used = 0;  // of those, inside their field at the solution
  bool converged() const {
    return termination != PoseGraphTermination::kMaxIterations &&
           termination != PoseGraphTermination::kTrustRegionCollapsed;
  }
  std::string report() const;  // one line for logs
};

// Solves in place (graph->poses). Throws covox::Error when the graph is invalid (see
// validate_pose_graph).
PoseGraphSolverSummary solve_pose_graph(
    Se3PoseGraph* graph, Device device,
    const PoseGraphSolverOptions& options = PoseGraphSolverOptions());
PoseGraphSolverSummary solve_pose_graph(
    PoseGraph4Dof* graph, Device device,
    const PoseGraphSolverOptions& options = PoseGraphSolverOptions());

// The 4-DoF graph with dense registration terms (registration_terms.h) next to its constraints.
// The terms' points and maps must live on `device`. Throws covox::Error when the graph or a term
// is invalid (validate_pose_graph, validate_registration_terms).
PoseGraphSolverSummary solve_pose_graph(
    PoseGraph4Dof* graph, const std::vector<RegistrationTerm>& registration, Device device,
    const PoseGraphSolverOptions& options = PoseGraphSolverOptions());

// One evaluation at the current poses, read back to the host: for tests (CPU/GPU parity,
// Jacobians against numeric differences) and diagnostics.
struct PoseGraphEvaluation {
  int dimension = 0;  // D
  double cost = 0.0;
  std::vector<double> residuals;       // D per constraint (whitened)
  std::vector<double> jacobians_from;  // D x D row-major per constraint (whitened)
  std::vector<double> jacobians_to;
  std::vector<double> gradient;                 // J^T f, D per vertex (zero at the fixed vertex)
  std::vector<double> hessian_diagonal_blocks;  // D x D per vertex (identity at the fixed vertex)
};
PoseGraphEvaluation evaluate_pose_graph(const Se3PoseGraph& graph, Device device);
PoseGraphEvaluation evaluate_pose_graph(const PoseGraph4Dof& graph, Device device);
// With registration terms: the cost, gradient and diagonal blocks include them (residuals and
// Jacobians are those of the constraints only).
PoseGraphEvaluation evaluate_pose_graph(const PoseGraph4Dof& graph,
                                        const std::vector<RegistrationTerm>& registration,
                                        Device device);

}  // namespace backend
}  // namespace covox

#include "covoxslam/backend/pose_graph_solver.h"

#include <sstream>

#include "covoxslam/backend/internal/pose_graph_solver_ops.h"

namespace covox {
namespace backend {

const char* to_string(PoseGraphTermination termination) {
  switch (termination) {
    case PoseGraphTermination::kFunctionTolerance:
      return "function tolerance";
    case PoseGraphTermination::kGradientTolerance:
      return "gradient tolerance";
    case PoseGraphTermination::kParameterTolerance:
      return "parameter tolerance";
    case PoseGraphTermination::kMaxIterations:
      return "max iterations";
    case PoseGraphTermination::kTrustRegionCollapsed:
      return "trust region collapsed";
    case PoseGraphTermination::kNoConstraints:
      return "no constraints";
  }
  return "unknown";
}

const char* to_string(PcgPreconditioner preconditioner) {
  return preconditioner == PcgPreconditioner::kBlockJacobi ? "block-Jacobi" : "odometry chain";
}

std::string PoseGraphSolverSummary::report() const {
  std::ostringstream out;
  out << "pose graph: cost " << initial_cost << " -> " << final_cost << " in " << iterations
      << " iterations (" << accepted_steps << " accepted, " << pcg_iterations
      << " PCG iterations), " << solve_time_s * 1e3 << " ms, stopped by " << to_string(termination);
  if (registration_points > 0) {
    out << "; registration points " << registration_points_used << " of " << registration_points
        << " used";
  }
  return out.str();
}

namespace {

template <class Model>
PoseGraphSolverSummary solve_any(PoseGraph<Model>* graph, Device device,
                                 const PoseGraphSolverOptions& options) {
  validate_pose_graph(*graph);
  return dispatch(device,
                  [&](auto backend) { return solve_pose_graph_on(backend, graph, options); });
}

template <class Model>
PoseGraphEvaluation evaluate_any(const PoseGraph<Model>& graph, Device device) {
  validate_pose_graph(graph);
  return dispatch(device, [&](auto backend) { return evaluate_pose_graph_on(backend, graph); });
}

}  // namespace

PoseGraphSolverSummary solve_pose_graph(Se3PoseGraph* graph, Device device,
                                        const PoseGraphSolverOptions& options) {
  return solve_any(graph, device, options);
}
PoseGraphSolverSummary solve_pose_graph(PoseGraph4Dof* graph, Device device,
                                        const PoseGraphSolverOptions& options) {
  return solve_any(graph, device, options);
}
PoseGraphSolverSummary solve_pose_graph(PoseGraph4Dof* graph,
                                        const std::vector<RegistrationTerm>& registration,
                                        Device device, const PoseGraphSolverOptions& options) {
  validate_pose_graph(*graph);
  validate_registration_terms(registration, static_cast<int32_t>(graph->poses.size()), device);
  return dispatch(device, [&](auto backend) {
    return solve_pose_graph_on(backend, graph, registration, options);
  });
}
PoseGraphEvaluation evaluate_pose_graph(const PoseGraph4Dof& graph,
                                        const std::vector<RegistrationTerm>& registration,
                                        Device device) {
  validate_pose_graph(graph);
  validate_registration_terms(registration, static_cast<int32_t>(graph.poses.size()), device);
  return dispatch(
      device, [&](auto backend) { return evaluate_pose_graph_on(backend, graph, registration); });
}
PoseGraphEvaluation evaluate_pose_graph(const Se3PoseGraph& graph, Device device) {
  return evaluate_any(graph, device);
}
PoseGraphEvaluation evaluate_pose_graph(const PoseGraph4Dof& graph, Device device) {
  return evaluate_any(graph, device);
}

}  // namespace backend
}  // namespace covox

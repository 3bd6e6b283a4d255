#pragma once
// The backend-templated entry points behind pose_graph_solver.h, defined in
// pose_graph_solver_impl.h and instantiated once per backend (src/backend/*_cpu.cpp,
// cuda/backend/*.cu).
#include <vector>

#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/registration_terms.h"

namespace covox {
namespace backend {

template <class Backend, class Model>
PoseGraphSolverSummary solve_pose_graph_on(Backend backend, PoseGraph<Model>* graph,
                                           const PoseGraphSolverOptions& options);

template <class Backend, class Model>
PoseGraphEvaluation evaluate_pose_graph_on(Backend backend, const PoseGraph<Model>& graph);

template <class Backend>
PoseGraphSolverSummary solve_pose_graph_on(Backend backend, PoseGraph4Dof* graph,
                                           const std::vector<RegistrationTerm>& registration,
                                           const PoseGraphSolverOptions& options);

template <class Backend>
PoseGraphEvaluation evaluate_pose_graph_on(Backend backend, const PoseGraph4Dof& graph,
                                           const std::vector<RegistrationTerm>& registration);

}  // namespace backend
}  // namespace covox

#pragma once
// The backend-templated entry points behind pose_graph_solver.h, defined in
// pose_graph_solver_impl.h and instantiated once per backend (src/backend/*_cpu.cpp,
// cuda/backend/*.cu).
#include "covoxslam/backend/pose_graph_solver.h"

namespace covox {
namespace backend {

template <class Backend, class Model>
PoseGraphSolverSummary solve_pose_graph_on(Backend backend, PoseGraph<Model>* graph,
                                           const PoseGraphSolverOptions& options);

template <class Backend, class Model>
PoseGraphEvaluation evaluate_pose_graph_on(Backend backend, const PoseGraph<Model>& graph);

}  // namespace backend
}  // namespace covox

// CPU (OpenMP) instantiation of the pose-graph solver.
#include "covoxslam/backend/internal/pose_graph_solver_impl.h"

namespace covox {
namespace backend {
COVOX_INSTANTIATE_POSE_GRAPH_SOLVER(CpuBackend, Se3Model)
COVOX_INSTANTIATE_POSE_GRAPH_SOLVER(CpuBackend, FourDofModel)
COVOX_INSTANTIATE_POSE_GRAPH_REGISTRATION(CpuBackend)
}  // namespace backend
}  // namespace covox

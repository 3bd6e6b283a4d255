// CUDA instantiation of the pose-graph solver (same source as the CPU twin).
#include "covoxslam/backend/internal/pose_graph_solver_impl.h"

namespace covox {
namespace backend {
COVOX_INSTANTIATE_POSE_GRAPH_SOLVER(CudaBackend, Se3Model)
COVOX_INSTANTIATE_POSE_GRAPH_SOLVER(CudaBackend, FourDofModel)
COVOX_INSTANTIATE_POSE_GRAPH_REGISTRATION(CudaBackend)
}  // namespace backend
}  // namespace covox

// CUDA instantiation of marching-cubes extraction (same source as the CPU twin).
#include "covoxslam/integrators/internal/mesh_integrator_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_MESH_INTEGRATOR(CudaBackend)
}  // namespace covox::integrators

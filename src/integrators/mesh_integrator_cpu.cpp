// CPU (OpenMP) instantiation of marching-cubes extraction.
#include "covoxslam/integrators/internal/mesh_integrator_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_MESH_INTEGRATOR(CpuBackend)
}  // namespace covox::integrators

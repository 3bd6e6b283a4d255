// CUDA instantiation of TSDF integration (same source as the CPU twin).
#include "covoxslam/integrators/internal/tsdf_integrator_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_TSDF_INTEGRATOR(CudaBackend)
}  // namespace covox::integrators

// CUDA instantiation of the ESDF update (same source as the CPU twin).
#include "covoxslam/integrators/internal/esdf_integrator_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_ESDF_INTEGRATOR(CudaBackend)
}  // namespace covox::integrators

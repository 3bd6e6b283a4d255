// CPU (OpenMP) instantiation of TSDF integration.
#include "covoxslam/integrators/internal/tsdf_integrator_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_TSDF_INTEGRATOR(CpuBackend)
}  // namespace covox::integrators

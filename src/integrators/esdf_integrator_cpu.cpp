// CPU (OpenMP) instantiation of the ESDF update.
#include "covoxslam/integrators/internal/esdf_integrator_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_ESDF_INTEGRATOR(CpuBackend)
}  // namespace covox::integrators

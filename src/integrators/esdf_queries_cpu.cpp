// CPU (OpenMP) instantiation of the ESDF queries.
#include "covoxslam/integrators/internal/esdf_queries_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_ESDF_QUERIES(CpuBackend)
}  // namespace covox::integrators

// CUDA instantiation of the ESDF queries (same source as the CPU twin).
#include "covoxslam/integrators/internal/esdf_queries_impl.h"

namespace covox::integrators {
COVOX_INSTANTIATE_ESDF_QUERIES(CudaBackend)
}  // namespace covox::integrators

// CPU (OpenMP) instantiation of the wall search's grid scores.
#include "covoxslam/pipeline/internal/wall_search_impl.h"

namespace covox::pipeline::internal {
COVOX_INSTANTIATE_WALL_SEARCH(CpuBackend)
}  // namespace covox::pipeline::internal

// CUDA instantiation of the wall search's grid scores (same source as the CPU twin).
#include "covoxslam/pipeline/internal/wall_search_impl.h"

namespace covox::pipeline::internal {
COVOX_INSTANTIATE_WALL_SEARCH(CudaBackend)
}  // namespace covox::pipeline::internal

// CUDA instantiation of the voxel pool operations (same source as the CPU twin).
#include "covoxslam/map/internal/voxel_pool_ops_impl.h"

namespace covox::map {
COVOX_INSTANTIATE_VOXEL_POOL_OPS(CudaBackend)
}  // namespace covox::map

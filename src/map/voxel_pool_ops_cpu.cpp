// CPU (OpenMP) instantiation of the voxel pool operations.
#include "covoxslam/map/internal/voxel_pool_ops_impl.h"

namespace covox::map {
COVOX_INSTANTIATE_VOXEL_POOL_OPS(CpuBackend)
}  // namespace covox::map

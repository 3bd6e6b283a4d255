// CPU (OpenMP) instantiation of the BlockHashTable algorithms.
#include "covoxslam/map/internal/block_hash_table_impl.h"

namespace covox::map {
COVOX_INSTANTIATE_BLOCK_HASH_TABLE(CpuBackend)
}  // namespace covox::map

// CUDA instantiation of the BlockHashTable algorithms (same source as the CPU twin).
#include "covoxslam/map/internal/block_hash_table_impl.h"

namespace covox::map {
COVOX_INSTANTIATE_BLOCK_HASH_TABLE(CudaBackend)
}  // namespace covox::map

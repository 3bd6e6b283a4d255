// CUDA instantiation of the submap codec's kernels (same source as the CPU twin).
#include "covoxslam/io/internal/submap_codec_kernels_impl.h"

namespace covox::io::internal {
COVOX_INSTANTIATE_SUBMAP_CODEC_KERNELS(CudaBackend)
}  // namespace covox::io::internal

// CPU (OpenMP) instantiation of the submap codec's kernels.
#include "covoxslam/io/internal/submap_codec_kernels_impl.h"

namespace covox::io::internal {
COVOX_INSTANTIATE_SUBMAP_CODEC_KERNELS(CpuBackend)
}  // namespace covox::io::internal

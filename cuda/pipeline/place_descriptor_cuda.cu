// CUDA instantiation of the place descriptor's surface columns (same source as the CPU twin).
#include "covoxslam/pipeline/internal/place_descriptor_impl.h"

namespace covox {
namespace pipeline {
COVOX_INSTANTIATE_PLACE_DESCRIPTOR(CudaBackend)
}  // namespace pipeline
}  // namespace covox

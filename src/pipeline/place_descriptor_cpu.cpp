// CPU (OpenMP) instantiation of the place descriptor's surface columns.
#include "covoxslam/pipeline/internal/place_descriptor_impl.h"

namespace covox {
namespace pipeline {
COVOX_INSTANTIATE_PLACE_DESCRIPTOR(CpuBackend)
}  // namespace pipeline
}  // namespace covox

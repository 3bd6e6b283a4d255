// CUDA instantiation of the runtime-dispatched primitives (same source as the CPU twin).
#include "covoxslam/core/internal/device_algorithms_impl.h"

namespace covox {
namespace algorithms {
template struct Primitives<CudaBackend>;
}  // namespace algorithms
}  // namespace covox

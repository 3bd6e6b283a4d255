// CPU (OpenMP) instantiation of the runtime-dispatched primitives.
#include "covoxslam/core/internal/device_algorithms_impl.h"

namespace covox {
namespace algorithms {
template struct Primitives<CpuBackend>;
}  // namespace algorithms
}  // namespace covox

// CPU (OpenMP) instantiation of submap registration.
#include "covoxslam/backend/internal/registration_impl.h"

namespace covox {
namespace backend {
COVOX_INSTANTIATE_REGISTRATION(CpuBackend)
}  // namespace backend
}  // namespace covox

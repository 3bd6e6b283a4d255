// CPU (OpenMP) instantiation of submap registration.
#include "covoxslam/backend/internal/registration_batch_impl.h"
#include "covoxslam/backend/internal/registration_impl.h"

namespace covox {
namespace backend {
COVOX_INSTANTIATE_REGISTRATION(CpuBackend)
COVOX_INSTANTIATE_REGISTRATION_BATCH(CpuBackend)
}  // namespace backend
}  // namespace covox

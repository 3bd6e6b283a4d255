// CUDA instantiation of submap registration (same source as the CPU twin).
#include "covoxslam/backend/internal/registration_impl.h"

namespace covox {
namespace backend {
COVOX_INSTANTIATE_REGISTRATION(CudaBackend)
}  // namespace backend
}  // namespace covox

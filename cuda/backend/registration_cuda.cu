// CUDA instantiation of submap registration (same source as the CPU twin).
#include "covoxslam/backend/internal/registration_batch_impl.h"
#include "covoxslam/backend/internal/registration_impl.h"

namespace covox {
namespace backend {
COVOX_INSTANTIATE_REGISTRATION(CudaBackend)
COVOX_INSTANTIATE_REGISTRATION_BATCH(CudaBackend)
}  // namespace backend
}  // namespace covox

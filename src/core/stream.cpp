#include "covoxslam/core/stream.h"

#include <string>
#include <utility>

#include "covoxslam/core/error.h"

#if COVOX_WITH_CUDA
#include <cuda_runtime_api.h>
#endif

namespace covox {

Stream::Stream(Device device) : device_(device) {}

Stream Stream::create(Device device) {
  Stream stream(device);
#if COVOX_WITH_CUDA
  if (device == Device::kCuda) {
    cudaStream_t handle = nullptr;
    const cudaError_t status = cudaStreamCreateWithFlags(&handle, cudaStreamNonBlocking);
    if (status != cudaSuccess) {
      throw Error(std::string("could not create a CUDA stream: ") + cudaGetErrorString(status));
    }
    stream.handle_ = handle;
    stream.owned_ = true;
  }
#endif
  return stream;
}

Stream::Stream(Stream&& other) noexcept
    : device_(other.device_),
      handle_(std::exchange(other.handle_, nullptr)),
      owned_(std::exchange(other.owned_, false)) {}

Stream& Stream::operator=(Stream&& other) noexcept {
  if (this != &other) {
    this->~Stream();
    device_ = other.device_;
    handle_ = std::exchange(other.handle_, nullptr);
    owned_ = std::exchange(other.owned_, false);
  }
  return *this;
}

Stream::~Stream() {
#if COVOX_WITH_CUDA
  if (owned_ && handle_) cudaStreamDestroy(static_cast<cudaStream_t>(handle_));
#endif
  handle_ = nullptr;
  owned_ = false;
}

void Stream::synchronize() const {
#if COVOX_WITH_CUDA
  if (device_ != Device::kCuda) return;
  const cudaError_t status = cudaStreamSynchronize(static_cast<cudaStream_t>(handle_));
  if (status != cudaSuccess) {
    throw Error(std::string("CUDA stream failed: ") + cudaGetErrorName(status) + " (" +
                cudaGetErrorString(status) + ")");
  }
#endif
}

}  // namespace covox

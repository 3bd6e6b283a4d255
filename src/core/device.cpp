#include "covoxslam/core/device.h"

#include <omp.h>

#include <algorithm>
#include <cctype>
#include <sstream>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"

#if COVOX_WITH_CUDA
#include <cuda_runtime_api.h>
#endif

namespace covox {

const char* to_string(Device device) { return device == Device::kCuda ? "cuda" : "cpu"; }

DeviceRequest parse_device_request(const std::string& text) {
  std::string lower = text;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (lower == "auto") return DeviceRequest::kAuto;
  if (lower == "cpu") return DeviceRequest::kCpu;
  if (lower == "cuda" || lower == "gpu") return DeviceRequest::kCuda;
  throw Error("device: '" + text + "' is not a device; use one of cuda, cpu, auto");
}

bool cuda_backend_compiled() { return COVOX_WITH_CUDA != 0; }

bool cuda_device_available() {
#if COVOX_WITH_CUDA
  int count = 0;
  const cudaError_t status = cudaGetDeviceCount(&count);
  if (status != cudaSuccess) {
    cudaGetLastError();  // clear the sticky "no driver" error so later calls are unaffected
    return false;
  }
  return count > 0;
#else
  return false;
#endif
}

std::string describe_device(Device device) {
  std::ostringstream text;
  if (device == Device::kCuda) {
#if COVOX_WITH_CUDA
    int index = 0;
    cudaDeviceProp properties{};
    if (cudaGetDevice(&index) == cudaSuccess &&
        cudaGetDeviceProperties(&properties, index) == cudaSuccess) {
      text << "cuda:" << index << " " << properties.name << " (sm_" << properties.major
           << properties.minor << ", " << (properties.totalGlobalMem >> 20) << " MiB)";
      return text.str();
    }
#endif
    return "cuda (unavailable)";
  }
  text << "cpu (" << omp_get_max_threads() << " OpenMP threads)";
  return text.str();
}

Device select_device(DeviceRequest request) {
  switch (request) {
    case DeviceRequest::kCpu:
      return Device::kCpu;
    case DeviceRequest::kCuda:
      if (!cuda_backend_compiled()) {
        throw NotAvailableError(
            "device: 'cuda' was requested but this build has no CUDA backend "
            "(rebuild with -DCOVOX_WITH_CUDA=ON and nvcc available), or use device 'auto'/'cpu'");
      }
      if (!cuda_device_available()) {
        throw NotAvailableError(
            "device: 'cuda' was requested but no usable GPU was found (check nvidia-smi and "
            "CUDA_VISIBLE_DEVICES), or use device 'auto'/'cpu'");
      }
      return Device::kCuda;
    case DeviceRequest::kAuto:
      break;
  }
  if (cuda_device_available()) return Device::kCuda;
  log_info("device: auto selected the CPU backend (",
           cuda_backend_compiled() ? "no usable GPU found" : "built without CUDA", ")");
  return Device::kCpu;
}

std::vector<Device> available_devices() {
  std::vector<Device> devices{Device::kCpu};
  if (cuda_device_available()) devices.push_back(Device::kCuda);
  return devices;
}

}  // namespace covox

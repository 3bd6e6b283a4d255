#pragma once
#include <string>
#include <vector>

namespace covox {

// Where data lives and kernels run.
enum class Device { kCpu, kCuda };

// What a user asks for (the `device` parameter): `auto` means CUDA when a usable GPU is present,
// otherwise the CPU twin (with one log line saying so).
enum class DeviceRequest { kAuto, kCpu, kCuda };

const char* to_string(Device device);
// Parses "cpu", "cuda" or "auto"; throws covox::Error naming the bad value otherwise.
DeviceRequest parse_device_request(const std::string& text);

// True when this build has the CUDA backend and at least one GPU can be used.
bool cuda_device_available();
// Whether this build was compiled with the CUDA backend at all.
bool cuda_backend_compiled();
// A one-line description of the device (GPU name and memory, or CPU thread count).
std::string describe_device(Device device);

// Resolves a request to a device. `auto` falls back to the CPU with one log line when no GPU is
// usable; an explicit `cuda` without a usable GPU throws covox::NotAvailableError.
Device select_device(DeviceRequest request);

// The devices every test runs on: always the CPU, plus CUDA when a GPU is present.
std::vector<Device> available_devices();

// Backend tags. Algorithms are written once as templates over a tag and instantiated twice:
// in a .cpp under src/ (CpuBackend, OpenMP) and in a .cu under cuda/ (CudaBackend).
struct CpuBackend {
  static constexpr Device kDevice = Device::kCpu;
};
struct CudaBackend {
  static constexpr Device kDevice = Device::kCuda;
};

// Calls `function(CpuBackend{})` or `function(CudaBackend{})` for a runtime device. In a build
// without CUDA the CUDA branch does not exist, so nothing references the missing instantiation.
template <class Function>
decltype(auto) dispatch(Device device, Function&& function) {
#if COVOX_WITH_CUDA
  if (device == Device::kCuda) return function(CudaBackend{});
#else
  (void)device;
#endif
  return function(CpuBackend{});
}

}  // namespace covox

#pragma once
// Runs a parameterised test on every backend: always the CPU, and CUDA when a GPU is present
// (the CUDA instances skip with a message on machines without one, such as CI).
#include <gtest/gtest.h>

#include <string>

#include "covoxslam/core/device.h"

namespace covox {
namespace testing_support {

inline std::string device_test_name(const ::testing::TestParamInfo<Device>& info) {
  return to_string(info.param);
}

class DeviceTest : public ::testing::TestWithParam<Device> {
 protected:
  void SetUp() override {
    if (GetParam() == Device::kCuda && !cuda_device_available()) {
      GTEST_SKIP() << "no usable GPU on this machine: the CUDA instance of this test runs on the "
                      "GPU machine";
    }
  }
  Device device() const { return GetParam(); }
};

// Parity tests compare both backends and need a GPU.
inline bool require_gpu_or_skip_message(std::string* message) {
  if (cuda_device_available()) return true;
  *message = "no usable GPU on this machine: CPU/CUDA parity runs on the GPU machine";
  return false;
}

}  // namespace testing_support
}  // namespace covox

#define COVOX_INSTANTIATE_ON_ALL_DEVICES(Suite)                                          \
  INSTANTIATE_TEST_SUITE_P(AllDevices, Suite,                                            \
                           ::testing::Values(covox::Device::kCpu, covox::Device::kCuda), \
                           covox::testing_support::device_test_name)

#define COVOX_SKIP_WITHOUT_GPU()                                               \
  do {                                                                         \
    std::string skip_message;                                                  \
    if (!covox::testing_support::require_gpu_or_skip_message(&skip_message)) { \
      GTEST_SKIP() << skip_message;                                            \
    }                                                                          \
  } while (0)

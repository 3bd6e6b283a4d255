#pragma once
// Fixtures that are expensive to build (integrated submaps) and only read by the tests: built once
// per device and kept for the rest of the test binary.
#include <map>
#include <utility>

#include "covoxslam/core/device.h"

namespace covox {
namespace testing_support {

// build(device) the first time a call site asks for `device`, the kept result afterwards. Pass a
// lambda: its type is unique to the call site, so each call site gets its own cache (a function
// pointer would share one with every other call of the same signature).
template <class T, class Build>
const T& once_per_device(Device device, Build&& build) {
  static std::map<Device, T> cache;
  auto it = cache.find(device);
  if (it == cache.end()) it = cache.emplace(device, build(device)).first;
  return it->second;
}

}  // namespace testing_support
}  // namespace covox

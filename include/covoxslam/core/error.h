#pragma once
#include <stdexcept>
#include <string>

namespace covox {

// Every error covoxslam throws derives from this, so callers (the ROS layer, the offline runner)
// can catch one type and print what() - which always says what went wrong and what to do.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// The GPU (or host) could not provide the memory a buffer asked for.
class OutOfMemoryError : public Error {
 public:
  explicit OutOfMemoryError(const std::string& message) : Error(message) {}
};

// A feature was asked for that this build does not have (e.g. CUDA in a CPU-only build).
class NotAvailableError : public Error {
 public:
  explicit NotAvailableError(const std::string& message) : Error(message) {}
};

}  // namespace covox

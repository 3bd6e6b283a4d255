#pragma once
#include "covoxslam/core/device.h"

namespace covox {

// An ordered queue of work on one device. On CUDA it owns a cudaStream_t (kept as void* so this
// header needs no CUDA include); on the CPU work runs synchronously and the stream is a tag.
// Later stages (frontend, backend) each use their own stream so they can overlap.
class Stream {
 public:
  // The default stream of `device` (the legacy CUDA default stream, or the CPU).
  explicit Stream(Device device = Device::kCpu);
  // A new non-blocking stream of its own.
  static Stream create(Device device);

  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;
  Stream(Stream&& other) noexcept;
  Stream& operator=(Stream&& other) noexcept;
  ~Stream();

  Device device() const { return device_; }
  void* native_handle() const { return handle_; }  // cudaStream_t on CUDA, nullptr on CPU
  // Blocks until all work queued so far has finished; throws covox::Error on a CUDA fault.
  void synchronize() const;

 private:
  Device device_;
  void* handle_ = nullptr;
  bool owned_ = false;
};

}  // namespace covox

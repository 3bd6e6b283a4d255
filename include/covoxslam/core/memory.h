#pragma once
#include <cstddef>
#include <cstdint>

#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"

namespace covox {

// Raw memory on a device. Buffer<T> is the typed owner everyone should use; these are its
// building blocks. Allocation failures throw covox::OutOfMemoryError with the size requested and,
// on CUDA, the free/total memory of the GPU.
void* allocate_bytes(Device device, size_t bytes);
void free_bytes(Device device, void* pointer) noexcept;
// Freed GPU memory is kept for reuse, at most this many bytes (process-wide, default 256 MiB;
// 0: every free goes back to the driver at once; core/internal/allocation_cache.h). A no-op in a
// build without CUDA.
void set_device_memory_cache_limit(size_t bytes);

// Copies `bytes` between any two devices. When the destination is host memory (CPU) the call
// returns after the data has arrived; device-to-device copies are queued on `stream`. Small
// copies from the GPU (a frame's counts, up to 64 KiB) go through a page-locked buffer of the
// calling thread: a copy into pageable memory would be staged by the driver through a buffer of
// its own, an extra copy on every read-back.
void copy_bytes(void* destination, Device destination_device, const void* source,
                Device source_device, size_t bytes, const Stream& stream);
// A small copy to the host (at most kMaxBytes) queued on `stream` now and collected later: the
// GPU goes on with the work queued after it while the host waits for the copy alone, not for the
// stream. On the CPU the bytes are copied at once. It uses a page-locked buffer and an event of
// the calling thread, so each thread has at most one pending at a time (a second one throws).
class PendingReadBack {
 public:
  static constexpr size_t kMaxBytes = 256;
  PendingReadBack(const void* source, Device source_device, size_t bytes, const Stream& stream);
  ~PendingReadBack();  // waits for the copy if nobody did
  PendingReadBack(const PendingReadBack&) = delete;
  PendingReadBack& operator=(const PendingReadBack&) = delete;
  // Waits for the copy (on the GPU, for it and the work queued before it) and copies the bytes
  // to `destination`.
  void wait(void* destination);

 private:
  size_t bytes_;
  bool waited_ = false;
};

// A few bytes of page-locked host memory that GPU kernels write directly (a mapped allocation):
// a kernel that ends a stage leaves its results there and the host reads them once the stream is
// synchronised, with no device-to-host copy queued after the kernel. `device_data()` is the
// pointer kernels write through; on the CPU backend both are the same plain host memory. Zeroed
// when allocated.
class MappedHostBytes {
 public:
  MappedHostBytes(Device device, size_t bytes);
  ~MappedHostBytes();
  MappedHostBytes(const MappedHostBytes&) = delete;
  MappedHostBytes& operator=(const MappedHostBytes&) = delete;
  void* host_data() const { return host_; }
  void* device_data() const { return device_; }
  size_t size() const { return bytes_; }

 private:
  Device device_kind_;
  size_t bytes_;
  void* host_ = nullptr;
  void* device_ = nullptr;
};

// The tile descriptors of the single-pass scans queued on `stream` (single_pass_scan.h), at least
// `tiles` of them, and the epoch of the next scan: a fresh epoch per call, the descriptors zeroed
// (epoch 0, never current) when they grow and when the 30-bit epoch would wrap. One registry per
// process, by stream.
struct ScanDescriptors {
  uint64_t* words = nullptr;
  uint32_t epoch = 0;
};
ScanDescriptors single_pass_scan_descriptors(const Stream& stream, int64_t tiles);

// memset on a device, queued on `stream`.
void set_bytes(void* destination, Device device, int value, size_t bytes, const Stream& stream);

}  // namespace covox

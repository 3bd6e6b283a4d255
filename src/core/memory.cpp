#include "covoxslam/core/memory.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <unordered_map>
#include <sstream>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/core/internal/allocation_cache.h"

#if COVOX_WITH_CUDA
#include <cuda_runtime_api.h>
#endif

namespace covox {
namespace {

// Two cache lines: SIMD loads, no false sharing, and room for types aligned to the GPU's 128-byte
// lines (tsdf::MergeTally's counters), which the CPU twin allocates in host memory.
constexpr size_t kHostAlignmentBytes = 128;

std::string mebibytes(size_t bytes) {
  std::ostringstream text;
  text << (static_cast<double>(bytes) / (1024.0 * 1024.0)) << " MiB";
  return text.str();
}

#if COVOX_WITH_CUDA
void check(cudaError_t status, const char* what) {
  if (status == cudaSuccess) return;
  throw Error(std::string("CUDA error during ") + what + ": " + cudaGetErrorName(status) + " (" +
              cudaGetErrorString(status) + ")");
}
cudaMemcpyKind copy_kind(Device destination, Device source) {
  if (destination == Device::kCuda)
    return source == Device::kCuda ? cudaMemcpyDeviceToDevice : cudaMemcpyHostToDevice;
  return source == Device::kCuda ? cudaMemcpyDeviceToHost : cudaMemcpyHostToHost;
}

// The calling thread's page-locked staging buffer for small device-to-host copies (allocated on
// first use; freed when the thread ends).
constexpr size_t kStagedCopyMaxBytes = 64 * 1024;
void* staging_buffer() {
  struct Staging {
    void* data = nullptr;
    ~Staging() {
      if (data) cudaFreeHost(data);
    }
  };
  thread_local Staging staging;
  if (!staging.data)
    check(cudaMallocHost(&staging.data, kStagedCopyMaxBytes), "page-locked staging allocation");
  return staging.data;
}

// Device memory comes from the driver through one process-wide cache of freed blocks
// (internal/allocation_cache.h). It is never destroyed: buffers in static storage may be freed
// after any destructor of this file would have run.
constexpr size_t kDeviceCacheMaxBytes = size_t{256} << 20;
thread_local cudaError_t last_cuda_malloc_error = cudaSuccess;  // of this thread's last failure
internal::AllocationCache& device_allocation_cache() {
  static auto* cache = new internal::AllocationCache(
      internal::AllocationCache::Backend{
          [](size_t bytes) -> void* {
            void* pointer = nullptr;
            const cudaError_t status = cudaMalloc(&pointer, bytes);
            if (status == cudaSuccess) return pointer;
            last_cuda_malloc_error = status;
            cudaGetLastError();  // clear the error so that later calls do not report it
            return nullptr;
          },
          [](void* pointer) { cudaFree(pointer); }, [] { cudaDeviceSynchronize(); }},
      kDeviceCacheMaxBytes);
  return *cache;
}
#endif

// The calling thread's pending read-back: its bytes (page-locked when CUDA is built in), the
// event that marks the copy's end, and whether one is pending.
struct ReadBackSlot {
  unsigned char* pinned = nullptr;
  bool pending = false;
  bool from_gpu = false;
#if COVOX_WITH_CUDA
  cudaEvent_t done = nullptr;
#endif
  unsigned char host_bytes[PendingReadBack::kMaxBytes];
  ~ReadBackSlot() {
#if COVOX_WITH_CUDA
    if (done) cudaEventDestroy(done);
    if (pinned) cudaFreeHost(pinned);
#endif
  }
};
ReadBackSlot& read_back_slot() {
  thread_local ReadBackSlot slot;
  return slot;
}

}  // namespace

MappedHostBytes::MappedHostBytes(Device device, size_t bytes)
    : device_kind_(device), bytes_(bytes) {
  if (device == Device::kCpu) {
    host_ = std::calloc(bytes > 0 ? bytes : 1, 1);
    if (!host_)
      throw OutOfMemoryError("MappedHostBytes: " + std::to_string(bytes) + " bytes of host memory");
    device_ = host_;
    return;
  }
#if COVOX_WITH_CUDA
  check(cudaHostAlloc(&host_, bytes > 0 ? bytes : 1, cudaHostAllocMapped),
        "mapped page-locked allocation");
  std::memset(host_, 0, bytes);
  const cudaError_t status = cudaHostGetDevicePointer(&device_, host_, 0);
  if (status != cudaSuccess) {
    cudaFreeHost(host_);
    check(status, "mapped page-locked allocation's device pointer");
  }
#else
  throw NotAvailableError("MappedHostBytes: CUDA memory asked of a build without CUDA");
#endif
}

MappedHostBytes::~MappedHostBytes() {
  if (device_kind_ == Device::kCpu) {
    std::free(host_);
    return;
  }
#if COVOX_WITH_CUDA
  if (host_) cudaFreeHost(host_);
#endif
}

PendingReadBack::PendingReadBack(const void* source, Device source_device, size_t bytes,
                                 const Stream& stream)
    : bytes_(bytes) {
  if (bytes > kMaxBytes) {
    throw Error("PendingReadBack: " + std::to_string(bytes) + " bytes, at most " +
                std::to_string(kMaxBytes));
  }
  ReadBackSlot& slot = read_back_slot();
  if (slot.pending)
    throw Error("PendingReadBack: this thread has one pending already; wait for it first");
  slot.from_gpu = source_device == Device::kCuda;
  if (!slot.from_gpu) {
    std::memcpy(slot.host_bytes, source, bytes);
    slot.pending = true;
    return;
  }
#if COVOX_WITH_CUDA
  if (!slot.pinned) {
    void* pinned = nullptr;
    check(cudaMallocHost(&pinned, kMaxBytes), "page-locked read-back allocation");
    slot.pinned = static_cast<unsigned char*>(pinned);
  }
  if (!slot.done)
    check(cudaEventCreateWithFlags(&slot.done, cudaEventDisableTiming), "read-back event creation");
  cudaStream_t cuda_stream = stream.device() == Device::kCuda
                                 ? static_cast<cudaStream_t>(stream.native_handle())
                                 : nullptr;
  check(cudaMemcpyAsync(slot.pinned, source, bytes, cudaMemcpyDeviceToHost, cuda_stream),
        "PendingReadBack copy");
  check(cudaEventRecord(slot.done, cuda_stream), "PendingReadBack event");
  slot.pending = true;
#else
  (void)stream;
  throw NotAvailableError("PendingReadBack: CUDA memory used in a build without CUDA");
#endif
}

void PendingReadBack::wait(void* destination) {
  ReadBackSlot& slot = read_back_slot();
  if (waited_ || !slot.pending) throw Error("PendingReadBack::wait: nothing pending");
  waited_ = true;
  slot.pending = false;
#if COVOX_WITH_CUDA
  if (slot.from_gpu) check(cudaEventSynchronize(slot.done), "PendingReadBack wait");
#endif
  std::memcpy(destination, slot.from_gpu ? slot.pinned : slot.host_bytes, bytes_);
}

PendingReadBack::~PendingReadBack() {
  if (waited_) return;
  ReadBackSlot& slot = read_back_slot();
#if COVOX_WITH_CUDA
  // the copy must end before the buffer is reused (errors are the next call's to report)
  if (slot.from_gpu && slot.done) cudaEventSynchronize(slot.done);
#endif
  slot.pending = false;
}

void* allocate_bytes(Device device, size_t bytes) {
  if (bytes == 0) return nullptr;
  if (device == Device::kCuda) {
#if COVOX_WITH_CUDA
    void* pointer = device_allocation_cache().allocate(bytes);
    if (!pointer) {
      const cudaError_t status = last_cuda_malloc_error;
      size_t free_bytes_now = 0, total_bytes = 0;
      cudaMemGetInfo(&free_bytes_now, &total_bytes);
      throw OutOfMemoryError("GPU allocation of " + mebibytes(bytes) + " failed (" +
                             cudaGetErrorString(status) + "); the GPU has " +
                             mebibytes(free_bytes_now) + " free of " + mebibytes(total_bytes) +
                             ". Reduce the map size (larger voxels, shorter rays, smaller "
                             "submaps) or free GPU memory.");
    }
    return pointer;
#else
    throw NotAvailableError("allocate_bytes: CUDA memory requested in a build without CUDA");
#endif
  }
  const size_t rounded =
      (bytes + kHostAlignmentBytes - 1) / kHostAlignmentBytes * kHostAlignmentBytes;
  void* pointer = std::aligned_alloc(kHostAlignmentBytes, rounded);
  if (!pointer) throw OutOfMemoryError("host allocation of " + mebibytes(bytes) + " failed");
  return pointer;
}

void set_device_memory_cache_limit(size_t bytes) {
#if COVOX_WITH_CUDA
  device_allocation_cache().set_limit(bytes);
#else
  (void)bytes;
#endif
}

void free_bytes(Device device, void* pointer) noexcept {
  if (!pointer) return;
  if (device == Device::kCuda) {
#if COVOX_WITH_CUDA
    try {
      device_allocation_cache().free(pointer);
    } catch (...) {  // the cache could not record it: hand it back at once
      cudaFree(pointer);
    }
#endif
    return;
  }
  std::free(pointer);
}

void copy_bytes(void* destination, Device destination_device, const void* source,
                Device source_device, size_t bytes, const Stream& stream) {
  if (bytes == 0) return;
  if (destination_device == Device::kCpu && source_device == Device::kCpu) {
    std::memcpy(destination, source, bytes);
    return;
  }
#if COVOX_WITH_CUDA
  cudaStream_t cuda_stream = stream.device() == Device::kCuda
                                 ? static_cast<cudaStream_t>(stream.native_handle())
                                 : nullptr;
  if (destination_device == Device::kCpu && source_device == Device::kCuda &&
      bytes <= kStagedCopyMaxBytes) {
    void* staging = staging_buffer();
    check(cudaMemcpyAsync(staging, source, bytes, cudaMemcpyDeviceToHost, cuda_stream),
          "copy_bytes");
    check(cudaStreamSynchronize(cuda_stream), "copy_bytes synchronize");
    std::memcpy(destination, staging, bytes);
    return;
  }
  check(cudaMemcpyAsync(destination, source, bytes, copy_kind(destination_device, source_device),
                        cuda_stream),
        "copy_bytes");
  // Host destinations (and host sources, whose memory the caller may reuse) are complete on return.
  if (destination_device == Device::kCpu || source_device == Device::kCpu) {
    check(cudaStreamSynchronize(cuda_stream), "copy_bytes synchronize");
  }
#else
  (void)stream;
  throw NotAvailableError("copy_bytes: CUDA memory used in a build without CUDA");
#endif
}

void set_bytes(void* destination, Device device, int value, size_t bytes, const Stream& stream) {
  if (bytes == 0) return;
  if (device == Device::kCpu) {
    std::memset(destination, value, bytes);
    return;
  }
#if COVOX_WITH_CUDA
  cudaStream_t cuda_stream = stream.device() == Device::kCuda
                                 ? static_cast<cudaStream_t>(stream.native_handle())
                                 : nullptr;
  check(cudaMemsetAsync(destination, value, bytes, cuda_stream), "set_bytes");
#else
  (void)stream;
  throw NotAvailableError("set_bytes: CUDA memory used in a build without CUDA");
#endif
}

ScanDescriptors single_pass_scan_descriptors(const Stream& stream, int64_t tiles) {
  struct Descriptors {
    uint64_t* words = nullptr;
    int64_t capacity = 0;
    uint32_t last_epoch = 0;
  };
  static std::mutex mutex;
  static std::unordered_map<const void*, Descriptors> by_stream;  // kept for the process's life
  constexpr uint32_t kLastEpoch = (1u << 30) - 1u;
  // GPU memory whatever the stream's tag: the scan is a CUDA kernel, and a CPU-tagged stream
  // stands for the legacy default stream there (as in copy_bytes), keyed by its null handle.
  std::lock_guard<std::mutex> lock(mutex);
  Descriptors& d = by_stream[stream.native_handle()];
  if (d.capacity < tiles || d.last_epoch == kLastEpoch) {
    if (d.capacity < tiles) {
      // the words go back to the device cache, which hands them out again only after a device
      // synchronisation: the scans queued on this stream that still use them end first
      free_bytes(Device::kCuda, d.words);
      d.words = nullptr;
      d.capacity = std::max<int64_t>(tiles, std::max<int64_t>(2 * d.capacity, 1024));
      d.words = static_cast<uint64_t*>(
          allocate_bytes(Device::kCuda, static_cast<size_t>(d.capacity) * sizeof(uint64_t)));
    }
    set_bytes(d.words, Device::kCuda, 0, static_cast<size_t>(d.capacity) * sizeof(uint64_t),
              stream);
    d.last_epoch = 0;
  }
  ++d.last_epoch;  // from 1: zeroed words (epoch 0) are never current
  return ScanDescriptors{d.words, d.last_epoch};
}

}  // namespace covox

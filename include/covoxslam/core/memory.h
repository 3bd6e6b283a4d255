#pragma once
#include <cstddef>

#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"

namespace covox {

// Raw memory on a device. Buffer<T> is the typed owner everyone should use; these are its
// building blocks. Allocation failures throw covox::OutOfMemoryError with the size requested and,
// on CUDA, the free/total memory of the GPU.
void* allocate_bytes(Device device, size_t bytes);
void free_bytes(Device device, void* pointer) noexcept;

// Copies `bytes` between any two devices. When the destination is host memory (CPU) the call
// returns after the data has arrived; device-to-device copies are queued on `stream`.
void copy_bytes(void* destination, Device destination_device, const void* source,
                Device source_device, size_t bytes, const Stream& stream);
// memset on a device, queued on `stream`.
void set_bytes(void* destination, Device device, int value, size_t bytes, const Stream& stream);

// Host memory that data of `source` (a device) is read back into: page-locked for a GPU, so that
// a copy is one DMA (into pageable memory the driver stages the copy and waits for it itself),
// plain host memory otherwise.
void* allocate_readback_bytes(Device source, size_t bytes);
void free_readback_bytes(Device source, void* pointer) noexcept;

// A fixed array of readback memory (see above), for small figures read back every frame.
template <class T>
class ReadbackArray {
 public:
  ReadbackArray(Device source, size_t count)
      : source_(source), count_(count), data_(static_cast<T*>(allocate_readback_bytes(source, count * sizeof(T)))) {}
  ~ReadbackArray() { free_readback_bytes(source_, data_); }
  ReadbackArray(const ReadbackArray&) = delete;
  ReadbackArray& operator=(const ReadbackArray&) = delete;
  T* data() { return data_; }
  const T* data() const { return data_; }
  size_t size() const { return count_; }

 private:
  Device source_;
  size_t count_;
  T* data_;
};

}  // namespace covox

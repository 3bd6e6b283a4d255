#pragma once
#include <algorithm>
#include <cstddef>
#include <type_traits>
#include <utility>
#include <vector>

#include "covoxslam/core/memory.h"

namespace covox {

// A typed array on one device (host memory for the CPU backend, cudaMalloc'd memory for CUDA).
// Move-only. Elements must be trivially copyable: the same bytes are valid on either side.
template <class T>
class Buffer {
  static_assert(std::is_trivially_copyable<T>::value, "Buffer<T> needs a trivially copyable T");

 public:
  explicit Buffer(Device device = Device::kCpu, size_t size = 0) : device_(device) {
    allocate(size);
  }
  static Buffer from_host(Device device, const std::vector<T>& values,
                          const Stream& stream = Stream()) {
    Buffer buffer(device, values.size());
    buffer.copy_from_host(values.data(), values.size(), stream);
    return buffer;
  }

  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  Buffer(Buffer&& other) noexcept { swap(other); }
  Buffer& operator=(Buffer&& other) noexcept {
    if (this != &other) {
      release();
      swap(other);
    }
    return *this;
  }
  ~Buffer() { release(); }

  Device device() const { return device_; }
  size_t size() const { return size_; }
  size_t capacity() const { return capacity_; }
  bool empty() const { return size_ == 0; }
  size_t size_bytes() const { return size_ * sizeof(T); }
  T* data() { return data_; }
  const T* data() const { return data_; }

  // Changes the size, keeping the first min(old, new) elements. New elements are uninitialised.
  void resize(size_t size, const Stream& stream = Stream()) {
    if (size <= capacity_) {
      size_ = size;
      return;
    }
    T* old_data = data_;
    const size_t old_size = size_;
    data_ = nullptr;
    allocate(size);
    if (old_size > 0) copy_bytes(data_, device_, old_data, device_, old_size * sizeof(T), stream);
    stream.synchronize();
    free_bytes(device_, old_data);
  }
  // Changes the size without keeping the contents (scratch space): cheaper than resize().
  void resize_discard(size_t size) {
    if (size <= capacity_) {
      size_ = size;
      return;
    }
    release();
    allocate(size);
  }

  void copy_from_host(const T* values, size_t count, const Stream& stream = Stream()) {
    resize_discard(count);
    if (count > 0) copy_bytes(data_, device_, values, Device::kCpu, count * sizeof(T), stream);
  }
  void copy_from_host(const std::vector<T>& values, const Stream& stream = Stream()) {
    copy_from_host(values.data(), values.size(), stream);
  }
  std::vector<T> to_host(const Stream& stream = Stream()) const {
    std::vector<T> values(size_);
    if (size_ > 0) copy_bytes(values.data(), Device::kCpu, data_, device_, size_bytes(), stream);
    return values;
  }
  // Reads one element back to the host (a small synchronous copy).
  T element(size_t index, const Stream& stream = Stream()) const {
    T value;
    copy_bytes(&value, Device::kCpu, data_ + index, device_, sizeof(T), stream);
    return value;
  }
  // Copies `other` (possibly on another device) into this buffer, resizing it.
  void copy_from(const Buffer& other, const Stream& stream = Stream()) {
    resize_discard(other.size());
    if (size_ > 0) copy_bytes(data_, device_, other.data_, other.device_, size_bytes(), stream);
  }
  // Sets every byte of every element to `byte_value` (0 or 0xff are the useful ones).
  void fill_bytes(int byte_value, const Stream& stream = Stream()) {
    if (size_ > 0) set_bytes(data_, device_, byte_value, size_bytes(), stream);
  }

 private:
  void allocate(size_t size) {
    if (size > 0) data_ = static_cast<T*>(allocate_bytes(device_, size * sizeof(T)));
    size_ = size;
    capacity_ = size;
  }
  void release() noexcept {
    if (data_) free_bytes(device_, data_);
    data_ = nullptr;
    size_ = capacity_ = 0;
  }
  void swap(Buffer& other) noexcept {
    std::swap(device_, other.device_);
    std::swap(data_, other.data_);
    std::swap(size_, other.size_);
    std::swap(capacity_, other.capacity_);
  }

  Device device_ = Device::kCpu;
  T* data_ = nullptr;
  size_t size_ = 0;
  size_t capacity_ = 0;
};

}  // namespace covox

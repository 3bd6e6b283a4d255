#pragma once
// Stable radix sort of (unsigned key, value) pairs by the low `key_bits` bits of the keys, on both
// backends (CUB's begin/end bits on the GPU; an OpenMP LSD radix sort on the CPU twin), so both
// produce the same order. Keys are 64- or 32-bit; the value is any trivially copyable type (an
// index, or a TSDF visit record travelling with its key, so no gather follows). Integration keys
// are relative to the frame's box and need 20-30 bits: 3-4 passes of 8 bits instead of 8.
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

#include <omp.h>

#include "covoxslam/core/device.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/stream.h"

#if defined(__CUDACC__)
#include <cub/device/device_radix_sort.cuh>

#include "covoxslam/core/internal/cuda_check.cuh"
#include "covoxslam/core/internal/cuda_temporary_allocator.cuh"
#endif

namespace covox {

// `keys_alt` and `values_alt` are scratch arrays of at least `count` elements on the same device.
// Keys must be < 2^key_bits (bits above are ignored, so larger keys would sort wrongly). The
// result is left in whichever pair of arrays the last pass wrote, and the pointers are swapped so
// that `keys` / `values` name it: an odd number of passes then costs no copy back (up to 12 bytes
// per pair, and two more device operations).
template <class Key, class Value>
void radix_sort_pairs_swapping(CpuBackend, const Stream&, Key*& keys, Value*& values, int64_t count,
                               int key_bits, Key*& keys_alt, Value*& values_alt) {
  if (count <= 1 || key_bits <= 0) return;
  constexpr int kDigitBits = 8;
  constexpr int kDigits = 1 << kDigitBits;
  const int passes =
      (std::min(key_bits, static_cast<int>(8 * sizeof(Key))) + kDigitBits - 1) / kDigitBits;
  const int max_threads = omp_get_max_threads();
  std::vector<int64_t> offsets(static_cast<size_t>(max_threads) * kDigits);
  Key* source_keys = keys;
  Value* source_values = values;
  Key* target_keys = keys_alt;
  Value* target_values = values_alt;
  for (int pass = 0; pass < passes; ++pass) {
    const int shift = pass * kDigitBits;
#pragma omp parallel num_threads(max_threads)
    {
      // Each thread owns one contiguous chunk; digits are placed thread by thread in chunk
      // order, which keeps equal digits in input order (stable).
      const int threads = omp_get_num_threads();
      const int thread = omp_get_thread_num();
      const int64_t begin = count * thread / threads;
      const int64_t end = count * (thread + 1) / threads;
      int64_t* histogram = offsets.data() + static_cast<size_t>(thread) * kDigits;
      std::fill(histogram, histogram + kDigits, 0);
      for (int64_t i = begin; i < end; ++i) ++histogram[(source_keys[i] >> shift) & (kDigits - 1)];
#pragma omp barrier
#pragma omp single
      {
        int64_t running = 0;
        for (int digit = 0; digit < kDigits; ++digit) {
          for (int t = 0; t < threads; ++t) {
            const int64_t n = offsets[static_cast<size_t>(t) * kDigits + digit];
            offsets[static_cast<size_t>(t) * kDigits + digit] = running;
            running += n;
          }
        }
      }
      for (int64_t i = begin; i < end; ++i) {
        const int64_t position = histogram[(source_keys[i] >> shift) & (kDigits - 1)]++;
        target_keys[position] = source_keys[i];
        target_values[position] = source_values[i];
      }
    }
    std::swap(source_keys, target_keys);
    std::swap(source_values, target_values);
  }
  if (source_keys != keys) {  // an odd number of passes left the result in the scratch arrays
    std::swap(keys, keys_alt);
    std::swap(values, values_alt);
  }
}

#if defined(__CUDACC__)
template <class Key, class Value>
void radix_sort_pairs_swapping(CudaBackend, const Stream& stream, Key*& keys, Value*& values,
                               int64_t count, int key_bits, Key*& keys_alt, Value*& values_alt) {
  if (count <= 1 || key_bits <= 0) return;
  const auto cuda_stream = static_cast<cudaStream_t>(stream.native_handle());
  cub::DoubleBuffer<Key> key_buffers(keys, keys_alt);
  cub::DoubleBuffer<Value> value_buffers(values, values_alt);
  const int end_bit = std::min(key_bits, static_cast<int>(8 * sizeof(Key)));
  size_t temporary_bytes = 0;
  cuda_check(cub::DeviceRadixSort::SortPairs(nullptr, temporary_bytes, key_buffers, value_buffers,
                                             count, 0, end_bit, cuda_stream),
             "radix sort (sizing)");
  CudaTemporaryAllocator allocator{stream.native_handle()};
  char* temporary = allocator.allocate(static_cast<std::ptrdiff_t>(temporary_bytes));
  cuda_check(cub::DeviceRadixSort::SortPairs(temporary, temporary_bytes, key_buffers, value_buffers,
                                             count, 0, end_bit, cuda_stream),
             "radix sort");
  allocator.deallocate(temporary, temporary_bytes);
  if (key_buffers.Current() != keys) {
    std::swap(keys, keys_alt);
    std::swap(values, values_alt);
  }
}
#endif

// The sorted pairs back in `keys` / `values` (a copy after an odd number of passes).
template <class Backend>
void radix_sort_pairs(Backend backend, const Stream& stream, uint64_t* keys, uint32_t* values,
                      int64_t count, int key_bits, uint64_t* keys_alt, uint32_t* values_alt) {
  uint64_t* sorted_keys = keys;
  uint32_t* sorted_values = values;
  radix_sort_pairs_swapping(backend, stream, sorted_keys, sorted_values, count, key_bits, keys_alt,
                            values_alt);
  if (sorted_keys != keys) {
    copy_bytes(keys, Backend::kDevice, sorted_keys, Backend::kDevice,
               static_cast<size_t>(count) * sizeof(uint64_t), stream);
    copy_bytes(values, Backend::kDevice, sorted_values, Backend::kDevice,
               static_cast<size_t>(count) * sizeof(uint32_t), stream);
  }
}

// How many bits a key needs to hold values up to `max_key` (at least 1).
inline int bits_for(uint64_t max_key) {
  int bits = 1;
  while (bits < 64 && (max_key >> bits) != 0) ++bits;
  return bits;
}

}  // namespace covox

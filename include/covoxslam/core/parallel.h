#pragma once
// Parallel primitives with one call site for both backends: parallel_for(backend, stream, n,
// functor) calls functor(i) for i in [0, n); exclusive_scan, sort_by_key, reduce_by_key, unique,
// reduce, count_if. `backend` is a tag (CpuBackend or CudaBackend). The CPU versions use OpenMP
// and Thrust's omp::par; the CUDA versions, visible only to nvcc, launch a kernel or use Thrust's
// cuda::par_nosync on the stream. Functors must be COVOX_HD (or `[=] COVOX_HD` lambdas). CUDA
// 11.4's Thrust/CUB 1.x lacks par_nosync and cub::DeviceReduce::TransformReduce: the version
// checks below pick `par` (the same results, a wait after each algorithm) and a reduction over a
// transforming iterator there.
#include <algorithm>
#include <cstdint>
#include <type_traits>
#include <vector>

#include <omp.h>

#include <thrust/count.h>
#include <thrust/reduce.h>
#include <thrust/scan.h>
#include <thrust/sort.h>
#include <thrust/transform_reduce.h>
#include <thrust/unique.h>
#include <thrust/system/omp/execution_policy.h>

#include "covoxslam/core/host_temporary_allocator.h"

#include "covoxslam/core/device.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/single_pass_scan.h"
#include "covoxslam/core/stream.h"

#if defined(__CUDACC__)
#include <cuda_runtime.h>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>
#include <thrust/system/cuda/execution_policy.h>
#if CUB_VERSION < 200400
#include <cub/iterator/transform_input_iterator.cuh>
#endif
#include "covoxslam/core/internal/cuda_check.cuh"
#include "covoxslam/core/internal/cuda_temporary_allocator.cuh"
#endif

namespace covox {

// --- execution policies -----------------------------------------------------------------------
// Temporary storage of both backends comes from a per-stream cache (see temporary_cache.h).
inline auto execution_policy(CpuBackend, const Stream& stream) {
  return thrust::omp::par(HostTemporaryAllocator{stream.native_handle()});
}
#if defined(__CUDACC__)
inline auto execution_policy(CudaBackend, const Stream& stream) {
  const auto cuda_stream = static_cast<cudaStream_t>(stream.native_handle());
#if THRUST_VERSION >= 101600
  return thrust::cuda::par_nosync(CudaTemporaryAllocator{stream.native_handle()}).on(cuda_stream);
#else
  return thrust::cuda::par(CudaTemporaryAllocator{stream.native_handle()}).on(cuda_stream);
#endif
}

namespace internal {
// cub::DeviceReduce::TransformReduce where CUB has it (2.4 and later), else the same reduction
// of transform(data[i]) through cub::TransformInputIterator; one signature for both.
template <class InputIterator, class Output, class Result, class Transform, class ReduceOp>
cudaError_t cub_transform_reduce(void* temporary, size_t& temporary_bytes, InputIterator data,
                                 Output out, int items, ReduceOp op, Transform transform,
                                 Result init, cudaStream_t cuda_stream) {
#if CUB_VERSION >= 200400
  return cub::DeviceReduce::TransformReduce(temporary, temporary_bytes, data, out, items, op,
                                            transform, init, cuda_stream);
#else
  const cub::TransformInputIterator<Result, Transform, InputIterator> values(data, transform);
  return cub::DeviceReduce::Reduce(temporary, temporary_bytes, values, out, items, op, init,
                                   cuda_stream);
#endif
}
}  // namespace internal
#endif

// --- parallel_for -----------------------------------------------------------------------------
template <class Functor>
void parallel_for(CpuBackend, const Stream&, int64_t count, const Functor& functor) {
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < count; ++i) functor(i);
}

#if defined(__CUDACC__)
namespace internal {
template <class Functor>
__global__ void parallel_for_kernel(int64_t count, Functor functor) {
  const int64_t i = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < count) functor(i);
}
}  // namespace internal

template <class Functor>
void parallel_for(CudaBackend, const Stream& stream, int64_t count, const Functor& functor) {
  if (count <= 0) return;
  constexpr int kThreadsPerBlock = 256;
  const int64_t blocks = (count + kThreadsPerBlock - 1) / kThreadsPerBlock;
  internal::parallel_for_kernel<<<static_cast<unsigned>(blocks), kThreadsPerBlock, 0,
                                  static_cast<cudaStream_t>(stream.native_handle())>>>(count,
                                                                                       functor);
  cuda_check(cudaGetLastError(), "parallel_for kernel launch");
}
#endif

// --- Thrust-backed primitives (same body for both backends) -----------------------------------

// out[i] = sum of in[0..i); `in` and `out` may alias.
template <class T>
void exclusive_scan(CpuBackend backend, const Stream& stream, const T* in, int64_t count, T* out) {
  if (count <= 0) return;
  thrust::exclusive_scan(execution_policy(backend, stream), in, in + count, out, T(0));
}
// out[i] = value_of(0) + ... + value_of(i - 1) for 32-bit values, value_of called once per i (see
// single_pass_scan.h for the GPU version). Here the values are written to `out` and scanned there;
// for a functor `out` (scan_output), to a temporary array first, then handed to it.
template <int kItems = kScanItemsPerThread, class ValueOf, class Output>
void exclusive_scan_of(CpuBackend backend, const Stream& stream, int64_t count,
                       const ValueOf& value_of, Output out) {
  if (count <= 0) return;
  if constexpr (std::is_pointer<Output>::value) {
    parallel_for(backend, stream, count, [&](int64_t i) { out[i] = value_of(i); });
    thrust::exclusive_scan(execution_policy(backend, stream), out, out + count, out, 0u);
  } else {
    std::vector<uint32_t> prefixes(static_cast<size_t>(count));
    uint32_t* scanned = prefixes.data();
    parallel_for(backend, stream, count, [&](int64_t i) { scanned[i] = value_of(i); });
    thrust::exclusive_scan(execution_policy(backend, stream), scanned, scanned + count, scanned,
                           0u);
    parallel_for(backend, stream, count, [&](int64_t i) { scan_output(out, i, scanned[i]); });
  }
}
// The same with a caller's scratch of `count` values for the CPU twin, which writes the values
// there and scans them in place before handing them to `out`: no temporary array per call (a
// fresh one for every large hash table activation would be paid again in page faults each
// time). The GPU's scan needs none (the overload below ignores it).
template <int kItems = kScanItemsPerThread, class ValueOf, class Output>
void exclusive_scan_of(CpuBackend backend, const Stream& stream, int64_t count,
                       const ValueOf& value_of, Output out, uint32_t* scratch) {
  if (count <= 0) return;
  parallel_for(backend, stream, count, [&](int64_t i) { scratch[i] = value_of(i); });
  thrust::exclusive_scan(execution_policy(backend, stream), scratch, scratch + count, scratch, 0u);
  parallel_for(backend, stream, count, [&](int64_t i) { scan_output(out, i, scratch[i]); });
}
#if defined(__CUDACC__)
template <int kItems = kScanItemsPerThread, class ValueOf, class Output>
void exclusive_scan_of(CudaBackend backend, const Stream& stream, int64_t count,
                       const ValueOf& value_of, Output out, uint32_t*) {
  exclusive_scan_of<kItems>(backend, stream, count, value_of, out);
}
#endif
#if defined(__CUDACC__)
// 32-bit values: the single-pass scan, one launch (single_pass_scan.h). Others: CUB directly
// (Thrust's scan adds a fixed overhead per call on top of CUB's).
template <class T>
void exclusive_scan(CudaBackend backend, const Stream& stream, const T* in, int64_t count, T* out) {
  if (count <= 0) return;
  if constexpr (std::is_same<T, uint32_t>::value) {
    exclusive_scan_of(backend, stream, count, internal::ArrayValues{in}, out);
  } else {
    const auto cuda_stream = static_cast<cudaStream_t>(stream.native_handle());
    size_t temporary_bytes = 0;
    cuda_check(cub::DeviceScan::ExclusiveSum(nullptr, temporary_bytes, in, out, count, cuda_stream),
               "exclusive_scan (sizing)");
    CudaTemporaryAllocator allocator{stream.native_handle()};
    char* temporary = allocator.allocate(static_cast<std::ptrdiff_t>(temporary_bytes));
    cuda_check(
        cub::DeviceScan::ExclusiveSum(temporary, temporary_bytes, in, out, count, cuda_stream),
        "exclusive_scan");
    allocator.deallocate(temporary, temporary_bytes);
  }
}
#endif

// Sorts ascending.
template <class Backend, class T>
void sort(Backend backend, const Stream& stream, T* data, int64_t count) {
  if (count <= 1) return;
  thrust::sort(execution_policy(backend, stream), data, data + count);
}

// Sorts keys ascending and permutes values along (stable).
template <class Backend, class Key, class Value>
void sort_by_key(Backend backend, const Stream& stream, Key* keys, Value* values, int64_t count) {
  if (count <= 1) return;
  thrust::stable_sort_by_key(execution_policy(backend, stream), keys, keys + count, values);
}

// Merges each run of consecutive keys that are `equal` with `op`, reading keys and values through
// any random-access iterators (e.g. a permutation of the updates); writes one key and one value
// per run and returns the number of runs.
//
// CPU: Thrust's OpenMP reduce_by_key is a generic, mostly serial algorithm, so the twin splits
// the keys into one chunk per thread at run boundaries, counts each chunk's runs, and reduces
// every run left to right in its chunk (deterministic, in input order). CUDA: Thrust's
// reduce_by_key (a segmented scan).
template <class KeyIterator, class ValueIterator, class Key, class Value, class Equal,
          class ReduceOp>
int64_t reduce_runs(CpuBackend, const Stream&, KeyIterator keys, ValueIterator values,
                    int64_t count, Key* keys_out, Value* values_out, Equal equal, ReduceOp op) {
  if (count <= 0) return 0;
  const int threads = omp_get_max_threads();
  std::vector<int64_t> begins(static_cast<size_t>(threads) + 1, count);
  begins[0] = 0;
  for (int t = 1; t < threads; ++t) {
    int64_t b = std::max(begins[t - 1], count * t / threads);
    while (b > 0 && b < count && equal(keys[b - 1], keys[b])) ++b;  // do not split a run
    begins[t] = b;
  }
  std::vector<int64_t> first_run(static_cast<size_t>(threads) + 1, 0);
#pragma omp parallel num_threads(threads)
  {
    const int t = omp_get_thread_num();
    int64_t runs = 0;
    for (int64_t i = begins[t]; i < begins[t + 1]; ++i)
      runs += (i == begins[t] || !equal(keys[i - 1], keys[i]));
    first_run[t + 1] = runs;
#pragma omp barrier
#pragma omp single
    for (int u = 0; u < threads; ++u) first_run[u + 1] += first_run[u];
    int64_t out = first_run[t] - 1;
    for (int64_t i = begins[t]; i < begins[t + 1]; ++i) {
      if (i == begins[t] || !equal(keys[i - 1], keys[i])) {
        keys_out[++out] = keys[i];
        values_out[out] = values[i];
      } else {
        values_out[out] = op(values_out[out], static_cast<Value>(values[i]));
      }
    }
  }
  return first_run[threads];
}
#if defined(__CUDACC__)
template <class KeyIterator, class ValueIterator, class Key, class Value, class Equal,
          class ReduceOp>
int64_t reduce_runs(CudaBackend backend, const Stream& stream, KeyIterator keys,
                    ValueIterator values, int64_t count, Key* keys_out, Value* values_out,
                    Equal equal, ReduceOp op) {
  if (count <= 0) return 0;
  auto ends = thrust::reduce_by_key(execution_policy(backend, stream), keys, keys + count, values,
                                    keys_out, values_out, equal, op);
  return static_cast<int64_t>(ends.first - keys_out);
}
#endif

// Merges each run of equal consecutive keys with `op`; returns the number of runs.
template <class Backend, class Key, class Value, class ReduceOp>
int64_t reduce_by_key(Backend backend, const Stream& stream, const Key* keys, const Value* values,
                      int64_t count, Key* keys_out, Value* values_out, ReduceOp op) {
  return reduce_runs(backend, stream, keys, values, count, keys_out, values_out,
                     thrust::equal_to<Key>(), op);
}

// Removes consecutive duplicates in place; returns the new count.
template <class Backend, class T>
int64_t unique(Backend backend, const Stream& stream, T* data, int64_t count) {
  if (count <= 0) return 0;
  return static_cast<int64_t>(
      thrust::unique(execution_policy(backend, stream), data, data + count) - data);
}

template <class Backend, class T, class ReduceOp>
T reduce(Backend backend, const Stream& stream, const T* data, int64_t count, T init, ReduceOp op) {
  if (count <= 0) return init;
  return thrust::reduce(execution_policy(backend, stream), data, data + count, init, op);
}

// op-reduction of transform(data[i]) (data: a pointer or any random-access iterator, such as a
// counting iterator for a transform that reads several arrays); Result must be trivially copyable.
template <class InputIterator, class Result, class Transform, class ReduceOp>
Result transform_reduce(CpuBackend backend, const Stream& stream, InputIterator data, int64_t count,
                        Transform transform, Result init, ReduceOp op) {
  if (count <= 0) return init;
  return thrust::transform_reduce(execution_policy(backend, stream), data, data + count, transform,
                                  init, op);
}
#if defined(__CUDACC__)
// CUB directly, result through a device temporary and one small copy: Thrust's version adds a
// fixed cost per call (its own temporary allocation and synchronisation) that a small
// per-frame reduction would pay every frame.
template <class InputIterator, class Result, class Transform, class ReduceOp>
Result transform_reduce(CudaBackend, const Stream& stream, InputIterator data, int64_t count,
                        Transform transform, Result init, ReduceOp op) {
  if (count <= 0) return init;
  const auto cuda_stream = static_cast<cudaStream_t>(stream.native_handle());
  size_t temporary_bytes = 0;
  cuda_check(
      internal::cub_transform_reduce(nullptr, temporary_bytes, data, static_cast<Result*>(nullptr),
                                     static_cast<int>(count), op, transform, init, cuda_stream),
      "transform_reduce (sizing)");
  // The result sits (aligned) in front of CUB's scratch: one allocation from the cache.
  const size_t result_bytes = (sizeof(Result) + 255) / 256 * 256;
  CudaTemporaryAllocator allocator{stream.native_handle()};
  char* temporary = allocator.allocate(static_cast<std::ptrdiff_t>(result_bytes + temporary_bytes));
  Result* result = reinterpret_cast<Result*>(temporary);
  cuda_check(
      internal::cub_transform_reduce(temporary + result_bytes, temporary_bytes, data, result,
                                     static_cast<int>(count), op, transform, init, cuda_stream),
      "transform_reduce");
  Result host;
  copy_bytes(&host, Device::kCpu, result, Device::kCuda, sizeof(Result), stream);  // staged, waits
  allocator.deallocate(temporary, result_bytes + temporary_bytes);
  return host;
}
#endif

// The same reduction left in the backend's memory at `out` (one Result), without waiting for it:
// later work on the stream reads it there, so a loop of reductions never stops for the host.
template <class InputIterator, class Result, class Transform, class ReduceOp>
void transform_reduce_into(CpuBackend backend, const Stream& stream, InputIterator data,
                           int64_t count, Transform transform, Result init, ReduceOp op,
                           Result* out) {
  *out = transform_reduce(backend, stream, data, count, transform, init, op);
}
#if defined(__CUDACC__)
template <class InputIterator, class Result, class Transform, class ReduceOp>
void transform_reduce_into(CudaBackend, const Stream& stream, InputIterator data, int64_t count,
                           Transform transform, Result init, ReduceOp op, Result* out) {
  const auto cuda_stream = static_cast<cudaStream_t>(stream.native_handle());
  const int items = static_cast<int>(std::max<int64_t>(count, 0));
  size_t temporary_bytes = 0;
  cuda_check(internal::cub_transform_reduce(nullptr, temporary_bytes, data, out, items, op,
                                            transform, init, cuda_stream),
             "transform_reduce_into (sizing)");
  temporary_bytes = std::max<size_t>(temporary_bytes, 1);
  // The scratch goes back to the stream's cache at once: work on one stream runs in order, so
  // whoever takes it next cannot start before this reduction has finished.
  CudaTemporaryAllocator allocator{stream.native_handle()};
  char* temporary = allocator.allocate(static_cast<std::ptrdiff_t>(temporary_bytes));
  cuda_check(internal::cub_transform_reduce(temporary, temporary_bytes, data, out, items, op,
                                            transform, init, cuda_stream),
             "transform_reduce_into");
  allocator.deallocate(temporary, temporary_bytes);
}
#endif

template <class Backend, class T, class Predicate>
int64_t count_if(Backend backend, const Stream& stream, const T* data, int64_t count,
                 Predicate predicate) {
  if (count <= 0) return 0;
  return static_cast<int64_t>(
      thrust::count_if(execution_policy(backend, stream), data, data + count, predicate));
}

}  // namespace covox

#pragma once
// Annotations that let one function body compile for both backends: nvcc sees
// __host__ __device__, a host compiler sees plain inline C++.

#if defined(__CUDACC__)
#define COVOX_HD __host__ __device__
#define COVOX_HD_INLINE __host__ __device__ __forceinline__
#else
#define COVOX_HD
#define COVOX_HD_INLINE inline __attribute__((always_inline))
#endif

// True while compiling device code (the second nvcc pass); false on every host pass.
#if defined(__CUDA_ARCH__)
#define COVOX_DEVICE_CODE 1
#else
#define COVOX_DEVICE_CODE 0
#endif

# The CUDA runtime as the imported target CUDA::cudart and the toolkit's header folders as
# CUDAToolkit_INCLUDE_DIRS. Included by the build (after enable_language(CUDA)) and by the
# installed package configuration.
#
# CMake 3.17+ has FindCUDAToolkit. CMake 3.16 (Ubuntu 20.04) has not: there the runtime library
# is looked up next to nvcc (or in the CUDA compiler's implicit link folders) and wrapped by hand.
if(TARGET CUDA::cudart)
  return()
endif()
if(NOT CMAKE_VERSION VERSION_LESS 3.17)
  find_package(CUDAToolkit REQUIRED)
  return()
endif()

set(covox_cuda_root "")
if(CMAKE_CUDA_COMPILER)
  get_filename_component(covox_cuda_root "${CMAKE_CUDA_COMPILER}" DIRECTORY)
  get_filename_component(covox_cuda_root "${covox_cuda_root}" DIRECTORY)
endif()
find_library(COVOX_CUDART_LIBRARY cudart
  HINTS ${CMAKE_CUDA_IMPLICIT_LINK_DIRECTORIES} ${covox_cuda_root}/lib64 ${covox_cuda_root}/lib
        /usr/local/cuda/lib64
  DOC "The CUDA runtime library (libcudart)")
find_path(COVOX_CUDA_RUNTIME_INCLUDE_DIR cuda_runtime.h
  HINTS ${CMAKE_CUDA_TOOLKIT_INCLUDE_DIRECTORIES} ${covox_cuda_root}/include /usr/local/cuda/include
  DOC "Folder holding cuda_runtime.h")
if(NOT COVOX_CUDART_LIBRARY OR NOT COVOX_CUDA_RUNTIME_INCLUDE_DIR)
  message(FATAL_ERROR "covoxslam: the CUDA runtime was not found (libcudart: '${COVOX_CUDART_LIBRARY}', "
                      "cuda_runtime.h: '${COVOX_CUDA_RUNTIME_INCLUDE_DIR}'); pass -DCOVOX_CUDART_LIBRARY=<path "
                      "of libcudart.so> and -DCOVOX_CUDA_RUNTIME_INCLUDE_DIR=<folder holding cuda_runtime.h>")
endif()
add_library(CUDA::cudart UNKNOWN IMPORTED)
set_target_properties(CUDA::cudart PROPERTIES
  IMPORTED_LOCATION "${COVOX_CUDART_LIBRARY}"
  INTERFACE_INCLUDE_DIRECTORIES "${COVOX_CUDA_RUNTIME_INCLUDE_DIR}")
set(CUDAToolkit_INCLUDE_DIRS ${COVOX_CUDA_RUNTIME_INCLUDE_DIR})

# Finds what the non-ROS library needs and describes it as one interface target,
# `covox_dependencies`, plus the function covox_configure_cuda_target().

# Eigen 3.3 or 3.4: its CMake package where installed (Debian), else a plain header folder (some
# GPU images ship only the headers). -DCOVOX_EIGEN_INCLUDE_DIR=<folder holding Eigen/Core> picks
# that folder even where the package is installed (e.g. to build against another version).
if(NOT COVOX_EIGEN_INCLUDE_DIR)
  find_package(Eigen3 3.3 QUIET NO_MODULE)
endif()
if(NOT TARGET Eigen3::Eigen)
  find_path(COVOX_EIGEN_INCLUDE_DIR Eigen/Core PATH_SUFFIXES eigen3
            DOC "Folder holding Eigen/Core")
  if(NOT COVOX_EIGEN_INCLUDE_DIR)
    message(FATAL_ERROR "covoxslam: Eigen 3 not found. Install libeigen3-dev (Debian/Ubuntu) or pass "
                        "-DCOVOX_EIGEN_INCLUDE_DIR=<folder holding Eigen/Core>.")
  endif()
  add_library(Eigen3::Eigen INTERFACE IMPORTED)
  set_target_properties(Eigen3::Eigen PROPERTIES INTERFACE_INCLUDE_DIRECTORIES ${COVOX_EIGEN_INCLUDE_DIR})
endif()
find_package(OpenMP REQUIRED COMPONENTS CXX)

# GoogleTest: the installed library where there is one, else built from its sources
# (Debian/Ubuntu ship them in /usr/src/googletest; COVOX_GTEST_SOURCE_DIR points elsewhere).
if(COVOX_BUILD_TESTS)
  find_package(GTest QUIET)
  if(NOT TARGET GTest::gtest)
    set(COVOX_GTEST_SOURCE_DIR /usr/src/googletest CACHE PATH "GoogleTest sources, used when no installed GTest is found")
    if(NOT EXISTS ${COVOX_GTEST_SOURCE_DIR}/CMakeLists.txt)
      message(FATAL_ERROR "covoxslam: GoogleTest not found. Install libgtest-dev, pass "
                          "-DCOVOX_GTEST_SOURCE_DIR=<googletest sources>, or -DCOVOX_BUILD_TESTS=OFF.")
    endif()
    set(INSTALL_GTEST OFF CACHE BOOL "" FORCE)
    set(BUILD_GMOCK OFF CACHE BOOL "" FORCE)
    add_subdirectory(${COVOX_GTEST_SOURCE_DIR} ${CMAKE_BINARY_DIR}/googletest EXCLUDE_FROM_ALL)
    add_library(GTest::gtest ALIAS gtest)
    add_library(GTest::gtest_main ALIAS gtest_main)
  endif()
endif()

# --- CUDA: optional. Without nvcc the CPU backend still builds and every test runs on it. -----
set(COVOX_CUDA_ENABLED OFF)
if(COVOX_WITH_CUDA)
  include(CheckLanguage)
  if(NOT CMAKE_CUDA_COMPILER AND EXISTS /usr/local/cuda/bin/nvcc)
    set(CMAKE_CUDA_COMPILER /usr/local/cuda/bin/nvcc)
  endif()
  check_language(CUDA)
  if(CMAKE_CUDA_COMPILER)
    # CMake 3.18+ turns CMAKE_CUDA_ARCHITECTURES into nvcc flags; 3.16/3.17 get explicit
    # -gencode flags from covox_configure_cuda_target() instead.
    set(CMAKE_CUDA_ARCHITECTURES ${COVOX_CUDA_ARCHITECTURES})
    enable_language(CUDA)
    if(CMAKE_VERSION VERSION_LESS 3.18)
      # CUDA_STANDARD knows 17 from CMake 3.18 on.
      set(CMAKE_CUDA_FLAGS "${CMAKE_CUDA_FLAGS} -std=c++17")
    else()
      set(CMAKE_CUDA_STANDARD 17)
      set(CMAKE_CUDA_STANDARD_REQUIRED ON)
    endif()
    include(CovoxCudaRuntime)
    set(COVOX_CUDA_ENABLED ON)
  else()
    message(WARNING "covoxslam: COVOX_WITH_CUDA is ON but no nvcc was found; building the CPU backend only")
  endif()
endif()

# --- Thrust/CUB (CCCL) headers: the CPU backend uses Thrust's OpenMP system, so they are needed
#     even without nvcc. CUDA 12.x/13.x ship them under include/cccl, older toolkits under include.
find_path(COVOX_THRUST_INCLUDE_DIR thrust/version.h
  HINTS ${CUDAToolkit_INCLUDE_DIRS} /usr/local/cuda/include
  PATH_SUFFIXES cccl
  DOC "Folder holding thrust/version.h (CCCL from the CUDA toolkit, or Debian's libthrust-dev)")
if(NOT COVOX_THRUST_INCLUDE_DIR)
  message(FATAL_ERROR "covoxslam: Thrust headers not found. Install the CUDA toolkit (CCCL) or "
                      "pass -DCOVOX_THRUST_INCLUDE_DIR=<folder holding thrust/version.h>.")
endif()

add_library(covox_dependencies INTERFACE)
target_include_directories(covox_dependencies SYSTEM INTERFACE ${COVOX_THRUST_INCLUDE_DIR})
target_link_libraries(covox_dependencies INTERFACE Eigen3::Eigen OpenMP::OpenMP_CXX)
# Host compilers see Thrust's OpenMP system as the "device" system, so no CUDA header is pulled
# into a .cpp file; nvcc keeps the CUDA system for .cu files.
target_compile_definitions(covox_dependencies INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:THRUST_DEVICE_SYSTEM=THRUST_DEVICE_SYSTEM_OMP>
  COVOX_WITH_CUDA=$<BOOL:${COVOX_CUDA_ENABLED}>)
target_compile_options(covox_dependencies INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wno-unknown-pragmas>)
if(COVOX_CUDA_ENABLED)
  target_link_libraries(covox_dependencies INTERFACE CUDA::cudart)
  target_compile_options(covox_dependencies INTERFACE
    $<$<COMPILE_LANGUAGE:CUDA>:--expt-relaxed-constexpr --extended-lambda -Xcompiler=-fopenmp -lineinfo>
    # No fused multiply-add contraction: the CPU twin does not contract either, and a voxel
    # boundary decided by one rounding differently would break CPU/GPU parity of the maps.
    $<$<COMPILE_LANGUAGE:CUDA>:--fmad=false>)
endif()

function(covox_configure_cuda_target target)
  if(NOT COVOX_CUDA_ENABLED)
    return()
  endif()
  set_target_properties(${target} PROPERTIES CUDA_SEPARABLE_COMPILATION OFF)
  if(CMAKE_VERSION VERSION_LESS 3.18)
    # What CUDA_ARCHITECTURES "87" means: SASS for sm_87 and PTX for compute_87.
    foreach(architecture ${COVOX_CUDA_ARCHITECTURES})
      if(NOT architecture MATCHES "^[0-9]+$")
        message(FATAL_ERROR "covoxslam: COVOX_CUDA_ARCHITECTURES entry '${architecture}' is not a "
                            "number; CMake ${CMAKE_VERSION} needs them spelled out (e.g. 72 or 87)")
      endif()
      target_compile_options(${target} PRIVATE
        "$<$<COMPILE_LANGUAGE:CUDA>:--generate-code=arch=compute_${architecture},code=[compute_${architecture},sm_${architecture}]>")
    endforeach()
  else()
    set_target_properties(${target} PROPERTIES CUDA_ARCHITECTURES "${COVOX_CUDA_ARCHITECTURES}")
  endif()
endfunction()

# An optional library: where find_package finds `package`, the interface target `target` links
# `imported` and defines `definition`=1 for the code that uses it. A macro, so that the package's
# _FOUND variable stays visible to the caller.
macro(covox_optional_library target package imported definition)
  find_package(${package} QUIET)
  if(${package}_FOUND)
    target_link_libraries(${target} INTERFACE ${imported})
    target_compile_definitions(${target} INTERFACE ${definition}=1)
  endif()
endmacro()

# --- Image codecs for the RGB-D dataset readers (io/). Optional: without them the readers say
#     which library is missing when asked for a PNG or JPEG, and everything else still works.
add_library(covox_image_codecs INTERFACE)
covox_optional_library(covox_image_codecs PNG PNG::PNG COVOX_HAVE_PNG)
covox_optional_library(covox_image_codecs JPEG JPEG::JPEG COVOX_HAVE_JPEG)
message(STATUS "covoxslam: PNG reader ${PNG_FOUND}, JPEG reader ${JPEG_FOUND}")

# --- zlib compresses the tools' PNG plots (eval/png_plot.h). Optional: without it a plot is
#     written in stored (uncompressed) deflate blocks, a few MB instead of tens of kB.
add_library(covox_zlib INTERFACE)
covox_optional_library(covox_zlib ZLIB ZLIB::ZLIB COVOX_HAVE_ZLIB)

# --- Decompressors for ROS bag chunks (io/rosbag_reader.h), for bags recorded with
#     `rosbag record --lz4` or `--bz2`. Optional: without them such a bag is refused with a message
#     naming the missing library, and uncompressed bags read as before.
add_library(covox_bag_codecs INTERFACE)
covox_optional_library(covox_bag_codecs LZ4 LZ4::LZ4 COVOX_HAVE_LZ4)
covox_optional_library(covox_bag_codecs BZip2 BZip2::BZip2 COVOX_HAVE_BZIP2)
if(NOT LZ4_FOUND)
  set(LZ4_FOUND FALSE)
endif()
if(NOT BZip2_FOUND)
  set(BZip2_FOUND FALSE)
endif()
message(STATUS "covoxslam: compressed bag chunks: lz4 ${LZ4_FOUND}, bz2 ${BZip2_FOUND}")

# --- Ceres: only a test and benchmark oracle for the pose-graph solver (never linked into the
#     library). Where it is missing (the GPU machine) the Ceres comparisons skip with a message.
find_package(Ceres QUIET)
add_library(covox_ceres_oracle INTERFACE)
if(Ceres_FOUND)
  target_link_libraries(covox_ceres_oracle INTERFACE Ceres::ceres)
  target_compile_definitions(covox_ceres_oracle INTERFACE COVOX_HAVE_CERES=1)
endif()
message(STATUS "covoxslam: Ceres oracle ${Ceres_FOUND}")

# The non-ROS library as one target per layer (the table in CovoxLayerTable.cmake): covox::core,
# covox::map, covox::integrators, covox::backend, covox::io and covox::pipeline, built from
# src/<layer>/*.cpp (host code and the CPU instantiations) and, with the CUDA backend,
# cuda/<layer>/*.cu (the CUDA instantiations of the same kernel headers). A layer's CPU and CUDA
# instantiations are in the same library, and it links exactly the layers it uses, so its
# libraries list no layer above it: static archives link in layer order without cycles, and a
# shared layer library (catkin builds shared ones) is linked with --no-undefined, so a call
# into a layer above fails its link. tools/scripts/check_layers.sh fails on an upward #include.
#
# covox::covoxslam (alias covoxslam::covoxslam) is the umbrella that links every layer, for the
# tools, the tests, the ROS layer and projects that use the installed package.
include(CovoxLayerTable)

set(COVOX_LAYER_TARGETS)
foreach(layer ${COVOX_LAYERS})
  file(GLOB layer_sources CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/src/${layer}/*.cpp)
  if(COVOX_CUDA_ENABLED)
    file(GLOB layer_cuda_sources CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/cuda/${layer}/*.cu)
    list(APPEND layer_sources ${layer_cuda_sources})
  endif()
  set(target covoxslam_${layer})
  add_library(${target} ${layer_sources})
  add_library(covox::${layer} ALIAS ${target})
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${layer})
  target_include_directories(${target} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:include>)
  target_link_libraries(${target} PUBLIC covox_dependencies)
  foreach(used ${COVOX_LAYER_USES_${layer}})
    if(NOT TARGET covoxslam_${used})
      message(FATAL_ERROR "covoxslam: layer '${layer}' uses '${used}', which is not a layer listed "
                          "before it in COVOX_LAYERS (${COVOX_LAYERS}); see cmake/CovoxLayerTable.cmake")
    endif()
    target_link_libraries(${target} PUBLIC covoxslam_${used})
  endforeach()
  get_target_property(target_type ${target} TYPE)
  if(target_type STREQUAL "SHARED_LIBRARY" AND CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang" AND NOT APPLE)
    target_link_options(${target} PRIVATE "LINKER:--no-undefined")
  endif()
  covox_configure_cuda_target(${target})
  list(INSERT COVOX_LAYER_TARGETS 0 ${target})  # top layer first: the link order
endforeach()

# The dataset readers decode PNG/JPEG images and lz4/bz2 bag chunks.
target_link_libraries(covoxslam_io PRIVATE covox_image_codecs covox_bag_codecs)

add_library(covoxslam INTERFACE)
target_link_libraries(covoxslam INTERFACE ${COVOX_LAYER_TARGETS})
add_library(covox::covoxslam ALIAS covoxslam)
add_library(covoxslam::covoxslam ALIAS covoxslam)

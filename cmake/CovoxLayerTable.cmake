# The library's layers, bottom first, and the layers each one may use: include headers of and
# link. One table for the build (CovoxLayers.cmake makes a target per layer that links exactly
# these) and for tools/scripts/check_layers.sh, which fails on an #include outside them. A layer
# may only use layers listed before it, so the table is also a valid build and link order.
#
# `cmake -P cmake/CovoxLayerTable.cmake` prints the table, one "layer: used layers" line each.
set(COVOX_LAYERS core map integrators backend io pipeline)
set(COVOX_LAYER_USES_core "")
set(COVOX_LAYER_USES_map core)
set(COVOX_LAYER_USES_integrators core map)
# Dense registration samples a submap's ESDF inside its kernels (integrators/esdf_lookup.h).
set(COVOX_LAYER_USES_backend core map integrators)
set(COVOX_LAYER_USES_io core map)
set(COVOX_LAYER_USES_pipeline core map integrators backend io)
# The ROS layer (src/ros, include/covoxslam/ros; CovoxRosTargets.cmake) is on top of all of them;
# it is checked like a layer but is not part of the library.
set(COVOX_LAYER_USES_ros ${COVOX_LAYERS})

if(CMAKE_SCRIPT_MODE_FILE STREQUAL CMAKE_CURRENT_LIST_FILE)
  foreach(layer ${COVOX_LAYERS} ros)
    string(REPLACE ";" " " uses "${COVOX_LAYER_USES_${layer}}")
    execute_process(COMMAND ${CMAKE_COMMAND} -E echo "${layer}: ${uses}")
  endforeach()
endif()

# Install rules: the library, its headers and its CMake package; the tools; with catkin, the ROS
# layer (nodelet library, node, nodelet_plugins.xml), launch/, rviz/ and config/ the way every
# ROS package lays them out, so that roslaunch, rosrun, nodelet and rviz find them in an install
# space. catkin installs package.xml and the generated messages itself.
#
# The CMake package exports covox::covoxslam, the umbrella, and the layer libraries it links
# (covox::core, covox::map, covox::integrators, covox::backend, covox::io, covox::pipeline), with
# covox::dependencies (the Eigen / OpenMP / Thrust / CUDA runtime interface they link),
# covox::image_codecs and covox::bag_codecs. Plain CMake installs
# lib/cmake/covoxslam/covoxslamConfig.cmake; under catkin the same targets come through catkin's
# own share/covoxslam/cmake/covoxslamConfig.cmake (its CFG_EXTRAS, cmake/covoxslam-extras.cmake
# .installspace.in), so catkin packages and plain CMake projects both find_package(covoxslam).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

if(COVOX_ROS_ENABLED)
  set(COVOX_INSTALL_LIBDIR ${CATKIN_PACKAGE_LIB_DESTINATION})
  set(COVOX_INSTALL_BINDIR ${CATKIN_PACKAGE_BIN_DESTINATION})  # lib/covoxslam: rosrun looks there
  set(COVOX_INSTALL_INCLUDEDIR ${CATKIN_GLOBAL_INCLUDE_DESTINATION})
  set(COVOX_INSTALL_SHAREDIR ${CATKIN_PACKAGE_SHARE_DESTINATION})
  set(COVOX_INSTALL_CMAKEDIR ${CATKIN_PACKAGE_SHARE_DESTINATION}/cmake)
else()
  set(COVOX_INSTALL_LIBDIR ${CMAKE_INSTALL_LIBDIR})
  set(COVOX_INSTALL_BINDIR ${CMAKE_INSTALL_BINDIR})
  set(COVOX_INSTALL_INCLUDEDIR ${CMAKE_INSTALL_INCLUDEDIR})
  set(COVOX_INSTALL_SHAREDIR ${CMAKE_INSTALL_DATADIR}/covoxslam)
  set(COVOX_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/covoxslam)
endif()

set_target_properties(covox_dependencies PROPERTIES EXPORT_NAME dependencies)
set_target_properties(covox_image_codecs PROPERTIES EXPORT_NAME image_codecs)
set_target_properties(covox_bag_codecs PROPERTIES EXPORT_NAME bag_codecs)
install(TARGETS covoxslam ${COVOX_LAYER_TARGETS} covox_dependencies covox_image_codecs covox_bag_codecs
        EXPORT covoxslamTargets
        ARCHIVE DESTINATION ${COVOX_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${COVOX_INSTALL_LIBDIR}
        RUNTIME DESTINATION ${COVOX_INSTALL_BINDIR})
install(DIRECTORY include/covoxslam DESTINATION ${COVOX_INSTALL_INCLUDEDIR})
install(EXPORT covoxslamTargets NAMESPACE covox:: DESTINATION ${COVOX_INSTALL_CMAKEDIR})
install(FILES cmake/CovoxCudaRuntime.cmake cmake/FindLZ4.cmake
              ${CMAKE_CURRENT_BINARY_DIR}/covoxslamDependencies.cmake
        DESTINATION ${COVOX_INSTALL_CMAKEDIR})

# What the exported interface links, recorded as it was found here (covoxslamDependencies.cmake
# finds it again where the package is used).
get_target_property(COVOX_EXPORT_EIGEN_INCLUDE_DIRS Eigen3::Eigen INTERFACE_INCLUDE_DIRECTORIES)
set(COVOX_EXPORT_CUDART_LIBRARY "")
set(COVOX_EXPORT_CUDA_RUNTIME_INCLUDE_DIR "")
if(COVOX_CUDA_ENABLED)
  get_target_property(COVOX_EXPORT_CUDART_LIBRARY CUDA::cudart IMPORTED_LOCATION)
  if(NOT COVOX_EXPORT_CUDART_LIBRARY)
    get_target_property(COVOX_EXPORT_CUDART_LIBRARY CUDA::cudart IMPORTED_LOCATION_RELEASE)
  endif()
  set(COVOX_EXPORT_CUDA_RUNTIME_INCLUDE_DIR ${CUDAToolkit_INCLUDE_DIRS})
endif()
configure_file(cmake/covoxslamDependencies.cmake.in ${CMAKE_CURRENT_BINARY_DIR}/covoxslamDependencies.cmake @ONLY)

if(NOT COVOX_ROS_ENABLED)
  configure_package_config_file(cmake/covoxslamConfig.cmake.in
    ${CMAKE_CURRENT_BINARY_DIR}/covoxslamConfig.cmake INSTALL_DESTINATION ${COVOX_INSTALL_CMAKEDIR})
  write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/covoxslamConfigVersion.cmake
    VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
  install(FILES ${CMAKE_CURRENT_BINARY_DIR}/covoxslamConfig.cmake
                ${CMAKE_CURRENT_BINARY_DIR}/covoxslamConfigVersion.cmake
          DESTINATION ${COVOX_INSTALL_CMAKEDIR})
endif()

install(DIRECTORY config/ DESTINATION ${COVOX_INSTALL_SHAREDIR}/config FILES_MATCHING PATTERN "*.yaml")

if(COVOX_BUILD_TOOLS)
  install(TARGETS ${COVOX_TOOL_TARGETS} RUNTIME DESTINATION ${COVOX_INSTALL_BINDIR})
endif()

if(COVOX_ROS_ENABLED)
  install(TARGETS covoxslam_ros LIBRARY DESTINATION ${COVOX_INSTALL_LIBDIR}
          ARCHIVE DESTINATION ${COVOX_INSTALL_LIBDIR})
  install(TARGETS covoxslam_node RUNTIME DESTINATION ${COVOX_INSTALL_BINDIR})
  install(FILES nodelet_plugins.xml DESTINATION ${COVOX_INSTALL_SHAREDIR})
  install(DIRECTORY launch rviz DESTINATION ${COVOX_INSTALL_SHAREDIR})
  # The rostest node and its launch files, for checking an install space (CI); a package
  # installed for use leaves them out.
  option(COVOX_INSTALL_TESTS "Install the rostest node and test/ros/*.test" OFF)
  if(COVOX_INSTALL_TESTS AND TARGET covoxslam_rostest_node)
    install(TARGETS covoxslam_rostest_node RUNTIME DESTINATION ${COVOX_INSTALL_BINDIR})
    install(DIRECTORY test/ros/ DESTINATION ${COVOX_INSTALL_SHAREDIR}/test FILES_MATCHING PATTERN "*.test")
  endif()
endif()

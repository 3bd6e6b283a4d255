# The catkin side of the package. Included before any target is defined, because catkin_package()
# decides where libraries and programs land (the devel space) and message generation must run
# before it. The ROS targets themselves (nodelet, node, rostest) come after the library, in
# CovoxRosTargets.cmake.
set(COVOX_ROS_ENABLED OFF)
find_package(catkin QUIET)
if(NOT catkin_FOUND)
  message(STATUS "covoxslam: catkin not found; building the non-ROS library, tools and tests only")
  return()
endif()

set(COVOX_ROS_COMPONENTS roscpp nodelet pluginlib tf2 tf2_ros tf2_eigen sensor_msgs nav_msgs geometry_msgs
    std_msgs std_srvs visualization_msgs diagnostic_msgs diagnostic_updater message_filters rosbag
    message_generation)
find_package(catkin QUIET COMPONENTS ${COVOX_ROS_COMPONENTS})
# catkin skips a missing component silently when QUIET: check each one, and without all of them
# build the non-ROS part only, naming what is missing (make deps installs it).
set(COVOX_ROS_MISSING)
foreach(component ${COVOX_ROS_COMPONENTS})
  if(NOT ${component}_FOUND)
    list(APPEND COVOX_ROS_MISSING ${component})
  endif()
endforeach()
if(COVOX_ROS_MISSING)
  message(WARNING "covoxslam: catkin was found but not the ROS packages [${COVOX_ROS_MISSING}]; the ROS layer "
                  "is not built (make deps installs them)")
  return()
endif()
set(COVOX_ROS_ENABLED ON)

add_message_files(DIRECTORY msg FILES LoopClosure.msg SubmapPose.msg SubmapPoses.msg)
add_service_files(DIRECTORY srv FILES EsdfQuery.srv FilePath.srv)
generate_messages(DEPENDENCIES std_msgs geometry_msgs)

# The nodelet library, then the library's layer libraries, top layer first (the link order):
# covoxslam itself is an interface target, with no file for catkin's users to link.
include(CovoxLayerTable)
set(COVOX_CATKIN_LIBRARIES covoxslam_ros)
foreach(layer ${COVOX_LAYERS})
  list(INSERT COVOX_CATKIN_LIBRARIES 1 covoxslam_${layer})
endforeach()
catkin_package(
  INCLUDE_DIRS include
  LIBRARIES ${COVOX_CATKIN_LIBRARIES}
  CATKIN_DEPENDS roscpp nodelet sensor_msgs nav_msgs geometry_msgs std_msgs std_srvs visualization_msgs
                 diagnostic_msgs diagnostic_updater message_runtime
  # The exported CMake targets (covox::covoxslam and the layers) in the install space: cmake/CovoxInstall.cmake.
  CFG_EXTRAS covoxslam-extras.cmake)

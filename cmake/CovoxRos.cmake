# The catkin side of the package. Included before any target is defined, because catkin_package()
# decides where libraries and programs land (the devel space).
set(COVOX_ROS_ENABLED OFF)
find_package(catkin QUIET)
if(NOT catkin_FOUND)
  message(STATUS "covoxslam: catkin not found; building the non-ROS library, tools and tests only")
  return()
endif()
set(COVOX_ROS_ENABLED ON)
catkin_package(
  INCLUDE_DIRS include
  LIBRARIES covoxslam)

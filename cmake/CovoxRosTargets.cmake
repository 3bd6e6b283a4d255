# The ROS 1 layer: the nodelet library (plugin covoxslam/CovoxSlamNodelet), the node wrapper and
# the rostest. Included at the end of CMakeLists.txt, after the library targets, when catkin and
# the ROS packages were found (CovoxRos.cmake).
file(GLOB COVOX_ROS_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/src/ros/*.cpp)
list(FILTER COVOX_ROS_SOURCES EXCLUDE REGEX ".*/covoxslam_node\\.cpp$")

add_library(covoxslam_ros ${COVOX_ROS_SOURCES})
target_include_directories(covoxslam_ros PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include ${CATKIN_DEVEL_PREFIX}/include)
target_include_directories(covoxslam_ros SYSTEM PUBLIC ${catkin_INCLUDE_DIRS})
target_link_libraries(covoxslam_ros PUBLIC covoxslam ${catkin_LIBRARIES})
add_dependencies(covoxslam_ros ${PROJECT_NAME}_generate_messages_cpp)

add_executable(covoxslam_node ${CMAKE_CURRENT_SOURCE_DIR}/src/ros/covoxslam_node.cpp)
target_link_libraries(covoxslam_node PRIVATE covoxslam_ros)

# The rostest: a gtest node that writes a short bag of a synthetic scene, plays it into the
# nodelet and checks topics, tf and services. Built with everything else (not EXCLUDE_FROM_ALL,
# as add_rostest_gtest would), so `cmake --build` + `ctest` runs it.
if(COVOX_BUILD_TESTS AND CATKIN_ENABLE_TESTING)
  find_package(rostest QUIET)
  if(rostest_FOUND)
    add_executable(covoxslam_rostest_node ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/covoxslam_rostest_node.cpp
                   ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/planner_rostest.cpp
                   ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/demo_flight_esdf_rostest.cpp
                   ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/world_mesh_reference.cpp)
    target_link_libraries(covoxslam_rostest_node PRIVATE covoxslam_ros GTest::gtest)
    # The start-up test runs the node binary by its path: rosrun skips everything under
    # <package>/build/, which is where `make` builds (rosrun's own exclusion rule).
    target_compile_definitions(covoxslam_rostest_node PRIVATE COVOXSLAM_NODE_PATH="$<TARGET_FILE:covoxslam_node>")
    add_dependencies(covoxslam_rostest_node covoxslam_node)
    add_rostest(test/ros/covoxslam_nodelet.test DEPENDENCIES covoxslam_rostest_node covoxslam_node covoxslam_ros)
    add_rostest(test/ros/covoxslam_nodelet_odometry.test DEPENDENCIES covoxslam_rostest_node covoxslam_node covoxslam_ros)
    add_rostest(test/ros/covoxslam_nodelet_depth.test DEPENDENCIES covoxslam_rostest_node covoxslam_node covoxslam_ros)
    add_rostest(test/ros/covoxslam_nodelet_planner.test DEPENDENCIES covoxslam_rostest_node covoxslam_node covoxslam_ros)
    # The demo-flight test simulates its flight with simulate_flight (a tool: COVOX_BUILD_TOOLS),
    # run by its build path as well.
    if(TARGET simulate_flight)
      target_compile_definitions(covoxslam_rostest_node PRIVATE COVOXSLAM_SIMULATE_FLIGHT_PATH="$<TARGET_FILE:simulate_flight>")
      add_dependencies(covoxslam_rostest_node simulate_flight)
      add_rostest(test/ros/covoxslam_demo_flight_esdf.test DEPENDENCIES covoxslam_rostest_node covoxslam_ros simulate_flight)
    endif()
  else()
    message(STATUS "covoxslam: rostest not found; the ROS integration test is not registered")
  endif()
endif()

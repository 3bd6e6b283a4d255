// covoxslam_node: the nodelet's SlamNode as a plain node (rosrun covoxslam covoxslam_node).
#include <exception>

#include <ros/ros.h>

#include "covoxslam/ros/slam_node.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "covoxslam");
  // Held outside the try: when the last node handle goes, roscpp shuts down and with it the
  // console, and the message saying which parameter is wrong would be lost.
  ros::NodeHandle node_handle;
  ros::NodeHandle private_node_handle("~");
  try {
    covox::ros_layer::SlamNode node(node_handle, private_node_handle);
    ros::spin();
  } catch (const std::exception& error) {
    ROS_FATAL_STREAM("covoxslam: cannot start: " << error.what());
    return 1;
  }
  return 0;
}

// covoxslam_node: the nodelet's SlamNode as a plain node (rosrun covoxslam covoxslam_node).
#include <exception>

#include <ros/ros.h>

#include "covoxslam/ros/slam_node.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "covoxslam");
  try {
    covox::ros_layer::SlamNode node(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& error) {
    ROS_FATAL_STREAM("covoxslam: cannot start: " << error.what());
    return 1;
  }
  return 0;
}

// The nodelet covoxslam/CovoxSlamNodelet: a SlamNode on the nodelet's node handles, so the
// clouds of a driver nodelet in the same manager arrive without serialisation.
#include <memory>

#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "covoxslam/ros/slam_node.h"

namespace covox {
namespace ros_layer {

class CovoxSlamNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      node_ = std::make_unique<SlamNode>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& error) {
      // A bad parameter: say which, and refuse to load (the manager reports the failed load).
      NODELET_FATAL_STREAM("covoxslam: cannot start: " << error.what());
      throw;
    }
  }
  std::unique_ptr<SlamNode> node_;
};

}  // namespace ros_layer
}  // namespace covox

PLUGINLIB_EXPORT_CLASS(covox::ros_layer::CovoxSlamNodelet, nodelet::Nodelet)

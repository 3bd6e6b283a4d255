#pragma once
// A tf tree read from a bag, for offline runs without ROS: every transform of /tf and
// /tf_static (and odometry given as nav_msgs/Odometry), looked up between any two connected
// frames at any time the dynamic transforms cover. Like tf2, it interpolates (linear in
// translation, slerp in rotation) and never extrapolates: a time outside a dynamic transform's
// samples is a failed lookup with the reason, which the caller counts as a dropped scan.
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/io/rosbag_messages.h"

namespace covox {
namespace io {
namespace rosbag {

class TfBuffer {
 public:
  // Adds T_parent_child at its header stamp. A static transform holds at every time (the latest
  // one given wins). Throws covox::Error when the child already has another parent (tf allows one
  // parent per frame) or a frame is its own parent.
  void add(const TransformStamped& transform, bool is_static);
  void add(const std::string& parent, const std::string& child, double stamp_s,
           const Eigen::Isometry3d& T_parent_child, bool is_static);

  // T_target_source at `stamp_s` (maps points in `source` to `target`). On failure returns false
  // and says why in `reason` (unknown frame, frames not connected, stamp outside a dynamic
  // transform's samples).
  bool lookup(const std::string& target, const std::string& source, double stamp_s,
              Eigen::Isometry3d* T_target_source, std::string* reason = nullptr) const;

  bool has_frame(const std::string& frame) const;
  size_t dynamic_sample_count() const;

 private:
  struct Sample {
    double stamp_s;
    Eigen::Isometry3d T_parent_child;
  };
  struct Edge {
    std::string parent;
    bool is_static = false;
    std::vector<Sample> samples;  // static: one; dynamic: sorted by stamp
  };
  // `frame` and its ancestors up to the root; empty when they form a loop.
  std::vector<std::string> ancestors(const std::string& frame) const;
  // T_ancestor_frame at `stamp_s`, `ancestor` being one of ancestors(frame).
  bool transform_to_ancestor(const std::string& frame, const std::string& ancestor, double stamp_s,
                             Eigen::Isometry3d* T_ancestor_frame, std::string* reason) const;
  static bool interpolate(const Edge& edge, double stamp_s, Eigen::Isometry3d* T_parent_child);

  std::map<std::string, Edge> edges_;  // by child frame
};

}  // namespace rosbag
}  // namespace io
}  // namespace covox

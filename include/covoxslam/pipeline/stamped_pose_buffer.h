#pragma once
// StampedPoseBuffer: recent odometry poses (from a nav_msgs/Odometry topic or any other stream
// of stamped poses), interpolated at a sensor stamp. The ROS layer keeps the clouds that arrive
// before the odometry covering their stamp and asks again until a timeout (see
// decide_pending()); this is the non-ROS part of that logic, tested in the main suite.
//
// Interpolation: linear in position, spherical-linear in rotation, between the two poses around
// the stamp. A stamp older than the buffer or inside a gap longer than max_gap_s is not
// interpolated (a long gap means the odometry stalled and the motion in between is unknown).
#include <cstddef>
#include <deque>

#include <Eigen/Geometry>

namespace covox {
namespace pipeline {

enum class PoseLookup {
  kOk,
  kEmpty,         // no pose yet
  kBeforeOldest,  // the stamp is older than every pose kept: it will never be answered
  kAfterNewest,   // the stamp is newer than the newest pose: it may be answered later
  kGap,           // the two poses around the stamp are more than max_gap_s apart
};
const char* to_string(PoseLookup lookup);

struct StampedPoseBufferConfig {
  double keep_s = 30.0;    // poses older than the newest minus this are forgotten
  double max_gap_s = 1.0;  // no interpolation across a longer gap
};

class StampedPoseBuffer {
 public:
  explicit StampedPoseBuffer(const StampedPoseBufferConfig& config = {});

  // Adds a pose; false (nothing added) when the stamp is not finite or not after the newest, or
  // the pose is not a finite rigid transform. The caller counts and logs refusals.
  bool add(double stamp_s, const Eigen::Isometry3d& pose);
  // The pose at `stamp_s` when the result is kOk.
  PoseLookup lookup(double stamp_s, Eigen::Isometry3d* pose) const;

  size_t size() const { return poses_.size(); }
  bool empty() const { return poses_.empty(); }
  double newest_stamp_s() const { return poses_.empty() ? 0.0 : poses_.back().stamp_s; }
  void clear() { poses_.clear(); }

 private:
  struct Entry {
    double stamp_s;
    Eigen::Vector3d position;
    Eigen::Quaterniond rotation;
  };
  StampedPoseBufferConfig config_;
  std::deque<Entry> poses_;
};

// What to do with a sensor message whose pose lookup gave `lookup` after waiting `waited_s`.
enum class PendingDecision {
  kUse,           // the pose is known: integrate
  kWait,          // not yet known but may be: keep it and ask again
  kDropTimedOut,  // waited longer than the timeout for a pose that never came
  kDropNever,     // can never be answered (older than the buffer, or inside a gap)
};
PendingDecision decide_pending(PoseLookup lookup, double waited_s, double timeout_s);

}  // namespace pipeline
}  // namespace covox

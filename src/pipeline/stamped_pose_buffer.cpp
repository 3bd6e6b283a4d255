#include "covoxslam/pipeline/stamped_pose_buffer.h"

#include <algorithm>
#include <cmath>

namespace covox {
namespace pipeline {

namespace {
bool is_finite_rigid(const Eigen::Isometry3d& pose) {
  if (!pose.matrix().allFinite()) return false;
  const Eigen::Matrix3d rotation = pose.linear();
  return (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <
             1e-3 &&
         rotation.determinant() > 0.0;
}
}  // namespace

const char* to_string(PoseLookup lookup) {
  switch (lookup) {
    case PoseLookup::kOk:
      return "ok";
    case PoseLookup::kEmpty:
      return "no pose received yet";
    case PoseLookup::kBeforeOldest:
      return "older than every pose kept";
    case PoseLookup::kAfterNewest:
      return "newer than the newest pose";
    case PoseLookup::kGap:
      return "inside a gap of the pose stream";
  }
  return "unknown";
}

StampedPoseBuffer::StampedPoseBuffer(const StampedPoseBufferConfig& config) : config_(config) {}

bool StampedPoseBuffer::add(double stamp_s, const Eigen::Isometry3d& pose) {
  if (!std::isfinite(stamp_s) || (!poses_.empty() && !(stamp_s > poses_.back().stamp_s)))
    return false;
  if (!is_finite_rigid(pose)) return false;
  poses_.push_back(
      Entry{stamp_s, pose.translation(), Eigen::Quaterniond(pose.linear()).normalized()});
  while (poses_.size() > 2 && poses_.front().stamp_s < stamp_s - config_.keep_s) poses_.pop_front();
  return true;
}

PoseLookup StampedPoseBuffer::lookup(double stamp_s, Eigen::Isometry3d* pose) const {
  if (poses_.empty()) return PoseLookup::kEmpty;
  if (!std::isfinite(stamp_s)) return PoseLookup::kBeforeOldest;
  if (stamp_s > poses_.back().stamp_s) return PoseLookup::kAfterNewest;
  if (stamp_s < poses_.front().stamp_s) return PoseLookup::kBeforeOldest;
  // First pose at or after the stamp.
  auto after =
      std::lower_bound(poses_.begin(), poses_.end(), stamp_s,
                       [](const Entry& entry, double stamp) { return entry.stamp_s < stamp; });
  Eigen::Vector3d position;
  Eigen::Quaterniond rotation;
  if (after->stamp_s == stamp_s) {
    position = after->position;
    rotation = after->rotation;
  } else {
    const Entry& before = *(after - 1);
    const double span_s = after->stamp_s - before.stamp_s;
    if (span_s > config_.max_gap_s) return PoseLookup::kGap;
    const double t = (stamp_s - before.stamp_s) / span_s;
    position = (1.0 - t) * before.position + t * after->position;
    rotation = before.rotation.slerp(t, after->rotation);
  }
  pose->setIdentity();
  pose->linear() = rotation.toRotationMatrix();
  pose->translation() = position;
  return PoseLookup::kOk;
}

PendingDecision decide_pending(PoseLookup lookup, double waited_s, double timeout_s) {
  switch (lookup) {
    case PoseLookup::kOk:
      return PendingDecision::kUse;
    case PoseLookup::kEmpty:
    case PoseLookup::kAfterNewest:
      return waited_s > timeout_s ? PendingDecision::kDropTimedOut : PendingDecision::kWait;
    case PoseLookup::kBeforeOldest:
    case PoseLookup::kGap:
      return PendingDecision::kDropNever;
  }
  return PendingDecision::kDropNever;
}

}  // namespace pipeline
}  // namespace covox

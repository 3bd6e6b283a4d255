#include "runner/scan_source.h"

#include <algorithm>

#include "covoxslam/core/log.h"

namespace covox {
namespace tools {

void log_dropped_scan(int64_t dropped_so_far, const std::string& reason, int64_t limit) {
  if (dropped_so_far <= limit || dropped_so_far % 100 == 0) {
    log_warning("scan dropped (", dropped_so_far, " so far",
                dropped_so_far == limit ? "; reporting every 100th from now" : "", "): ", reason);
  }
}

pipeline::SweepOdometry sweep_odometry(double stamp_s, const std::vector<float>& point_times_s,
                                       const PoseAtStamp& pose_at) {
  pipeline::SweepOdometry sweep;
  if (point_times_s.empty()) return sweep;
  const auto [earliest, latest] = std::minmax_element(point_times_s.begin(), point_times_s.end());
  sweep.begin_s = *earliest;
  sweep.end_s = *latest;
  sweep.known = pose_at(stamp_s + sweep.begin_s, &sweep.T_odom_sensor_begin) &&
                pose_at(stamp_s + sweep.end_s, &sweep.T_odom_sensor_end);
  return sweep;
}

io::StampedPose stamped_pose(double stamp_s, const Eigen::Isometry3d& pose) {
  io::StampedPose stamped;
  stamped.timestamp_s = stamp_s;
  stamped.position_m = pose.translation();
  stamped.orientation = Eigen::Quaterniond(pose.linear()).normalized();
  return stamped;
}

}  // namespace tools
}  // namespace covox

#include "runner/scan_source.h"

#include "covoxslam/core/log.h"

namespace covox {
namespace tools {

void log_dropped_scan(int64_t dropped_so_far, const std::string& reason, int64_t limit) {
  if (dropped_so_far <= limit || dropped_so_far % 100 == 0) {
    log_warning("scan dropped (", dropped_so_far, " so far",
                dropped_so_far == limit ? "; reporting every 100th from now" : "", "): ", reason);
  }
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

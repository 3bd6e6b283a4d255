#pragma once
// What the offline runner maps: a sequence of scans (points in the sensor frame with the
// sensor's odometry pose at the scan stamp) and, where the input has one, a reference trajectory
// to evaluate against. Implementations: a ROS bag (bag_scan_source.h) and the dataset folders of
// the shared data (dataset_scan_sources.h).
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/vec3.h"
#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/pipeline/sweep_odometry.h"

namespace covox {
namespace tools {

struct SourceScan {
  double stamp_s = 0.0;
  Eigen::Isometry3d T_odom_sensor = Eigen::Isometry3d::Identity();
  std::vector<Vec3f> points_sensor_m;
  std::vector<Rgb8> colors;  // empty, or one per point
  // Empty, or one per point: seconds after stamp_s at which the point was measured; `sweep`: the
  // odometry at the first and last point time (pipeline/sweep_odometry.h), for de-skewing.
  std::vector<float> point_times_s;
  pipeline::SweepOdometry sweep;
};

// How the reference trajectory may be called in a report: only ground truth is "accuracy".
enum class ReferenceKind { kNone, kGroundTruth, kOtherEstimate };

class ScanSource {
 public:
  virtual ~ScanSource() = default;
  // Scans the source will offer at most (for the progress bar).
  virtual size_t size() const = 0;
  // The next scan; false after the last. A scan that cannot be used (no odometry at its stamp,
  // an unreadable cloud) is skipped, counted in dropped() and logged (rate-limited).
  virtual bool next(SourceScan* scan) = 0;
  // What is being read, for the report.
  virtual std::string describe() const = 0;
  // Sensor seconds the input covers (for the real-time factor).
  virtual double duration_s() const = 0;
  int64_t dropped() const { return dropped_; }
  // The reference trajectory with its kind (position-only ground truth such as RTK fixes has
  // has_orientations false). Empty with kind kNone when the input has none.
  const io::Trajectory& reference() const { return reference_; }
  ReferenceKind reference_kind() const { return reference_kind_; }

 protected:
  int64_t dropped_ = 0;
  io::Trajectory reference_;
  ReferenceKind reference_kind_ = ReferenceKind::kNone;
};

// Logs at most the first `limit` problems and then every 100th, with the running count, so a bad
// input does not flood the terminal but is never silent.
void log_dropped_scan(int64_t dropped_so_far, const std::string& reason, int64_t limit = 5);

// The odometry across a scan's sweep: its first and last point time (seconds after `stamp_s`) and
// T_odom_sensor there from `pose_at` (false where it has none, which leaves the sweep unknown);
// unknown without point times.
using PoseAtStamp = std::function<bool(double stamp_s, Eigen::Isometry3d* T_odom_sensor)>;
pipeline::SweepOdometry sweep_odometry(double stamp_s, const std::vector<float>& point_times_s,
                                       const PoseAtStamp& pose_at);

// A pose of a trajectory (io::Trajectory) from a stamp and a rigid transform.
io::StampedPose stamped_pose(double stamp_s, const Eigen::Isometry3d& pose);

}  // namespace tools
}  // namespace covox

#include "runner/sim_scan_source.h"

#include <chrono>

#include "covoxslam/core/error.h"
#include "sim/sim_flight_bag.h"
#include "sim/sim_mission_bag.h"

namespace covox {
namespace tools {

SimScanSource::SimScanSource(const sim::SimulationOptions& options, double min_range_m,
                             size_t max_scans)
    : mission_(options, max_scans), min_range_m_(min_range_m) {
  const Eigen::Isometry3d T_sensor_lidar = sim::T_os1_sensor_os1_lidar();
  reference_.has_orientations = true;
  reference_.poses.reserve(mission_.size());
  for (const sim::StampedIsometry& truth : mission_.truth()) {
    const Eigen::Isometry3d T_world_lidar = truth.pose * T_sensor_lidar;
    io::StampedPose pose;
    pose.timestamp_s = sim::bag_stamp_s(truth.stamp_s);
    pose.position_m = T_world_lidar.translation();
    pose.orientation = Eigen::Quaterniond(T_world_lidar.linear()).normalized();
    reference_.poses.push_back(pose);
  }
  reference_kind_ = ReferenceKind::kGroundTruth;
}

bool SimScanSource::next(SourceScan* scan) {
  if (next_scan_ >= mission_.size()) return false;
  const auto start = std::chrono::steady_clock::now();
  const size_t k = next_scan_++;
  const sim::SweepScan sweep = mission_.scan(k);
  const std::vector<Eigen::Vector3f> points_lidar_m = sim::to_os1_lidar(sweep.points_sensor_m);
  // The odometry as the bag's tf gives it: looked up in the tf of this sweep, which holds the
  // bag's samples, at the stamp as the bag stores it.
  const sim::ArcheBagLayout layout;
  const io::rosbag::TfBuffer tf = sim::sweep_tf(mission_, k, layout);
  const PoseAtStamp pose_at = [&](double stamp_s, Eigen::Isometry3d* T_odom_sensor) {
    return tf.lookup(layout.odom_frame, layout.lidar_frame, stamp_s, T_odom_sensor);
  };
  scan->stamp_s = sim::bag_stamp_s(mission_.truth()[k].stamp_s);
  std::string reason;
  if (!tf.lookup(layout.odom_frame, layout.lidar_frame, scan->stamp_s, &scan->T_odom_sensor,
                 &reason)) {
    throw Error("simulated scan " + std::to_string(k) + ": " + reason);
  }
  scan->colors.clear();
  scan->points_sensor_m.clear();
  scan->points_sensor_m.reserve(points_lidar_m.size());
  scan->point_times_s.clear();
  scan->point_times_s.reserve(sweep.times_ns.size());
  // The same test, in the same precision, as BagScanSource's.
  const float min_range_squared = static_cast<float>(min_range_m_ * min_range_m_);
  for (size_t i = 0; i < points_lidar_m.size(); ++i) {
    const Eigen::Vector3f& p = points_lidar_m[i];
    if (p.squaredNorm() < min_range_squared) continue;
    scan->points_sensor_m.emplace_back(p.x(), p.y(), p.z());
    if (!sweep.times_ns.empty())
      scan->point_times_s.push_back(sim::point_time_s(sweep.times_ns[i]));
  }
  scan->sweep = sweep_odometry(scan->stamp_s, scan->point_times_s, pose_at);
  generation_s_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return true;
}

std::string SimScanSource::describe() const {
  return "simulated flight in process: " + sim::describe_flight(mission_) +
         ", ground-truth reference";
}

double SimScanSource::duration_s() const {
  const std::vector<sim::StampedIsometry>& truth = mission_.truth();
  if (truth.size() < 2) return 0.0;
  const double span_s = truth.back().stamp_s - truth.front().stamp_s;
  return span_s * truth.size() / (truth.size() - 1);  // plus one scan period
}

}  // namespace tools
}  // namespace covox

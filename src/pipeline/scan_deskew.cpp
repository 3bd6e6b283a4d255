#include "covoxslam/pipeline/scan_deskew.h"

#include <algorithm>
#include <cmath>

#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

const char* point_times_problem(const Scan& scan) {
  if (scan.point_times_s.empty()) return nullptr;
  if (scan.point_times_s.size() != scan.points_sensor_m.size()) {
    return "its point time count does not match its point count";
  }
  float earliest = scan.point_times_s.front(), latest = earliest;
  for (const float t : scan.point_times_s) {
    if (!std::isfinite(t)) return "a point time is not finite";
    earliest = std::min(earliest, t);
    latest = std::max(latest, t);
  }
  const SweepOdometry& sweep = scan.sweep;
  if (!sweep.known) return nullptr;
  if (!is_valid_rigid_pose(sweep.T_odom_sensor_begin) ||
      !is_valid_rigid_pose(sweep.T_odom_sensor_end)) {
    return "its sweep odometry is not a finite rigid transform";
  }
  // The sweep's times are a float's rounding away from the points' extremes at most.
  const double slack_s = 1e-4 + 1e-6 * std::max(std::abs(sweep.begin_s), std::abs(sweep.end_s));
  if (!std::isfinite(sweep.begin_s) || !std::isfinite(sweep.end_s) ||
      sweep.begin_s > earliest + slack_s || sweep.end_s < latest - slack_s) {
    return "its sweep odometry does not cover its point times";
  }
  return nullptr;
}

DeskewPlan plan_deskew(const DeskewConfig& config, const Scan& scan) {
  DeskewPlan plan;
  if (!config.enabled) {
    plan.outcome = DeskewOutcome::kDisabled;
  } else if (scan.point_times_s.empty()) {
    plan.outcome = DeskewOutcome::kNoPointTimes;
  } else if (!scan.sweep.known || !(scan.sweep.end_s > scan.sweep.begin_s)) {
    // A sweep of no duration (all points at one time) has nothing to undo either.
    plan.outcome = DeskewOutcome::kNoSweepOdometry;
  } else {
    plan.outcome = DeskewOutcome::kDeskewed;
    plan.motion = integrators::make_sweep_motion(scan.T_odom_sensor, scan.sweep.T_odom_sensor_begin,
                                                 scan.sweep.T_odom_sensor_end, scan.sweep.begin_s,
                                                 scan.sweep.end_s);
  }
  return plan;
}

integrators::PointCloudView upload_scan(const Scan& scan, const DeskewPlan& plan,
                                        Buffer<Vec3f>* points, Buffer<Rgb8>* colors,
                                        Buffer<float>* times_s, const Stream& stream) {
  const bool deskewed = plan.outcome == DeskewOutcome::kDeskewed;
  points->copy_from_host(scan.points_sensor_m, stream);
  colors->copy_from_host(scan.colors, stream);
  if (deskewed) times_s->copy_from_host(scan.point_times_s, stream);
  integrators::PointCloudView cloud;
  cloud.points = points->data();
  cloud.colors = scan.colors.empty() ? nullptr : colors->data();
  cloud.count = static_cast<int64_t>(scan.points_sensor_m.size());
  cloud.times_s = deskewed ? times_s->data() : nullptr;
  cloud.sweep = plan.motion;
  return cloud;
}

double motion_displacement_m(const Eigen::Isometry3d& T_a, const Eigen::Isometry3d& T_b,
                             double range_m) {
  const Eigen::Isometry3d T_ab = T_a.inverse() * T_b;
  return T_ab.translation().norm() + Eigen::AngleAxisd(T_ab.linear()).angle() * range_m;
}

}  // namespace pipeline
}  // namespace covox

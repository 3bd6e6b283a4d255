// The pipeline's side of de-skewing (pipeline/scan_deskew.h): which scans' times are refused,
// which scans are de-skewed, and that the SLAM system counts every outcome.
#include "covoxslam/pipeline/scan_deskew.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "covoxslam/pipeline/slam_system.h"
#include "support/analytic_scene.h"
#include "support/small_slam_config.h"

namespace covox {
namespace {

using pipeline::DeskewOutcome;
using pipeline::Scan;

Scan timed_scan(double stamp_s, double x_m) {
  testing_support::AnalyticScene scene;
  scene.shape = testing_support::Shape::kSphere;
  scene.radius = 4.0;
  Scan scan;
  scan.stamp_s = stamp_s;
  scan.T_odom_sensor.translation() = Eigen::Vector3d(x_m, 0.0, 0.0);
  scan.points_sensor_m =
      testing_support::simulate_lidar(scene, scan.T_odom_sensor, 64, 8, 40.0, 10.0);
  for (size_t i = 0; i < scan.points_sensor_m.size(); ++i)
    scan.point_times_s.push_back(0.1f * static_cast<float>(i) / scan.points_sensor_m.size());
  scan.sweep.known = true;
  scan.sweep.begin_s = 0.0;
  scan.sweep.end_s = scan.point_times_s.back();
  scan.sweep.T_odom_sensor_begin = scan.T_odom_sensor;
  scan.sweep.T_odom_sensor_end = scan.T_odom_sensor;
  scan.sweep.T_odom_sensor_end.translation().x() += 0.2;
  return scan;
}

TEST(ScanDeskew, RefusesTimesThatDoNotFitThePoints) {
  EXPECT_EQ(pipeline::point_times_problem(timed_scan(1.0, 0.0)), nullptr);
  Scan short_times = timed_scan(1.0, 0.0);
  short_times.point_times_s.pop_back();
  EXPECT_NE(pipeline::point_times_problem(short_times), nullptr);
  Scan nan_time = timed_scan(1.0, 0.0);
  nan_time.point_times_s[3] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(pipeline::point_times_problem(nan_time), nullptr);
  Scan bent_sweep = timed_scan(1.0, 0.0);
  bent_sweep.sweep.T_odom_sensor_end.linear()(0, 0) = 2.0;  // not a rotation
  EXPECT_NE(pipeline::point_times_problem(bent_sweep), nullptr);
  Scan short_sweep = timed_scan(1.0, 0.0);
  short_sweep.sweep.end_s = 0.5 * short_sweep.sweep.end_s;  // the last points lie beyond it
  EXPECT_NE(pipeline::point_times_problem(short_sweep), nullptr);
  Scan no_sweep = timed_scan(1.0, 0.0);
  no_sweep.sweep = pipeline::SweepOdometry();  // times alone are fine
  EXPECT_EQ(pipeline::point_times_problem(no_sweep), nullptr);
}

TEST(ScanDeskew, PlansDeskewingOnlyWithTimesAndSweepOdometry) {
  pipeline::DeskewConfig config;
  EXPECT_EQ(pipeline::plan_deskew(config, timed_scan(1.0, 0.0)).outcome, DeskewOutcome::kDeskewed);
  Scan untimed = timed_scan(1.0, 0.0);
  untimed.point_times_s.clear();
  EXPECT_EQ(pipeline::plan_deskew(config, untimed).outcome, DeskewOutcome::kNoPointTimes);
  Scan no_sweep = timed_scan(1.0, 0.0);
  no_sweep.sweep.known = false;
  EXPECT_EQ(pipeline::plan_deskew(config, no_sweep).outcome, DeskewOutcome::kNoSweepOdometry);
  config.enabled = false;
  EXPECT_EQ(pipeline::plan_deskew(config, timed_scan(1.0, 0.0)).outcome, DeskewOutcome::kDisabled);
  // The motion moves the last point by the sweep's 0.2 m along x.
  const pipeline::DeskewPlan plan = pipeline::plan_deskew({}, timed_scan(1.0, 0.0));
  EXPECT_NEAR(plan.motion.deskew(Vec3f(0, 0, 0), timed_scan(1.0, 0.0).sweep.end_s).x, 0.2f, 1e-5f);
}

TEST(ScanDeskew, DisplacementBoundsTheMotionAtTheRange) {
  Eigen::Isometry3d a = Eigen::Isometry3d::Identity(), b = a;
  b.translation() = Eigen::Vector3d(0.3, 0.4, 0.0);
  b.linear() = Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_NEAR(pipeline::motion_displacement_m(a, b, 20.0), 0.5 + 0.1 * 20.0, 1e-9);
}

TEST(ScanDeskew, SlamSystemCountsEveryOutcome) {
  pipeline::SlamConfig config = testing_support::small_slam_config();
  pipeline::SlamSystem slam(config);
  EXPECT_TRUE(slam.add_scan(timed_scan(1.0, 0.0)));  // de-skewed
  Scan no_sweep = timed_scan(1.1, 0.05);
  no_sweep.sweep.known = false;
  EXPECT_TRUE(slam.add_scan(no_sweep));  // times without the sweep's odometry
  Scan bad_times = timed_scan(1.2, 0.1);
  bad_times.point_times_s.resize(2);
  EXPECT_FALSE(slam.add_scan(bad_times));  // refused
  Scan still = timed_scan(1.3, 0.05);      // no times, barely moved
  still.point_times_s.clear();
  EXPECT_TRUE(slam.add_scan(still));
  Scan moving = timed_scan(1.4, 1.05);  // no times, a metre since the previous scan
  moving.point_times_s.clear();
  EXPECT_TRUE(slam.add_scan(moving));
  slam.finish();
  const pipeline::SlamCounters counters = slam.counters();
  EXPECT_EQ(counters.scans_integrated, 4);
  EXPECT_EQ(counters.scans_deskewed, 1);
  EXPECT_EQ(counters.scans_not_deskewed_no_sweep_odometry, 1);
  EXPECT_EQ(counters.scans_dropped_bad_point_times, 1);
  EXPECT_EQ(counters.scans_not_deskewed_no_times_moving, 1);
}

}  // namespace
}  // namespace covox

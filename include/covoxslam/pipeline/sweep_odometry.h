#pragma once
// A spinning LiDAR fires its columns over a sweep (an OS1 at 10 Hz: 0.1 s) while the robot
// moves, so each point of a cloud was measured from a slightly different pose. SweepOdometry is
// the sensor's odometry at the first and the last point time of a scan; with each point's time
// (Scan::point_times_s) the TSDF integrator moves every point into the sensor frame at the scan's
// stamp (de-skewing), the pose in between interpolated: linear in translation, along the shortest
// rotation (integrators/sweep_motion.h). See docs/design.md, "De-skewing".
#include <Eigen/Geometry>

namespace covox {
namespace pipeline {

struct SweepOdometry {
  // Seconds after the scan's stamp (negative: before it) of the first and the last point.
  double begin_s = 0.0;
  double end_s = 0.0;
  Eigen::Isometry3d T_odom_sensor_begin = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_odom_sensor_end = Eigen::Isometry3d::Identity();
  // False: no odometry across the sweep is known; the points are used as they are.
  bool known = false;
};

}  // namespace pipeline
}  // namespace covox

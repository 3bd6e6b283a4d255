#pragma once
// The pipeline's side of de-skewing (integrators/sweep_motion.h does the moving): whether a scan's
// point times and sweep odometry are usable, and the motion the TSDF integrator is given. A scan
// is de-skewed when de-skewing is on, it carries one time per point and the odometry across its
// sweep is known; otherwise its points are used as they are, and the reason is counted.
#include <Eigen/Geometry>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/sweep_motion.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

// nullptr when the scan's times and sweep are consistent, else what is wrong with them (a time
// count other than the point count, a non-finite time, a sweep with non-rigid poses or times
// that do not bracket the points' times).
const char* point_times_problem(const Scan& scan);

enum class DeskewOutcome {
  kDeskewed,
  kDisabled,        // deskew.enabled is false
  kNoPointTimes,    // the cloud carries no per-point time
  kNoSweepOdometry  // times, but the odometry across the sweep is unknown
};

struct DeskewPlan {
  DeskewOutcome outcome = DeskewOutcome::kNoPointTimes;
  integrators::SweepMotion motion;  // with kDeskewed
};

// What to do with a scan that passed point_times_problem().
DeskewPlan plan_deskew(const DeskewConfig& config, const Scan& scan);

// The cloud the TSDF integrator takes for `scan`: its points, its colours (when it has them) and,
// when `plan` de-skews it, its point times with the plan's motion, copied into the buffers (of
// the integrating device) on `stream`. The buffers must stay untouched until the integration is
// done.
integrators::PointCloudView upload_scan(const Scan& scan, const DeskewPlan& plan,
                                        Buffer<Vec3f>* points, Buffer<Rgb8>* colors,
                                        Buffer<float>* times_s, const Stream& stream);

// How far (m) a point `range_m` from the sensor moves between two poses: the translation plus the
// arc of the rotation. Between consecutive scans it bounds the distortion within one sweep.
double motion_displacement_m(const Eigen::Isometry3d& T_a, const Eigen::Isometry3d& T_b,
                             double range_m);

}  // namespace pipeline
}  // namespace covox

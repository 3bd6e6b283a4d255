#include "covoxslam/integrators/sweep_motion.h"

#include <cmath>
#include <string>

#include "covoxslam/core/eigen_conversions.h"
#include "covoxslam/core/error.h"

namespace covox::integrators {

SweepMotion make_sweep_motion(const Eigen::Isometry3d& T_odom_ref,
                              const Eigen::Isometry3d& T_odom_begin,
                              const Eigen::Isometry3d& T_odom_end, double begin_s, double end_s) {
  if (!T_odom_ref.matrix().allFinite() || !T_odom_begin.matrix().allFinite() ||
      !T_odom_end.matrix().allFinite()) {
    throw Error("de-skewing: a pose of the sweep is not finite");
  }
  if (!std::isfinite(begin_s) || !std::isfinite(end_s) || !(end_s > begin_s)) {
    throw Error("de-skewing: the sweep must end after it begins, got begin " +
                std::to_string(begin_s) + " s and end " + std::to_string(end_s) + " s");
  }
  const Eigen::Isometry3d T_begin_end = T_odom_begin.inverse() * T_odom_end;
  const Eigen::AngleAxisd rotation(T_begin_end.linear());
  const Eigen::Vector3d rotation_vector = rotation.axis() * rotation.angle();
  const Eigen::Vector3d translation = T_begin_end.translation();
  SweepMotion motion;
  motion.T_ref_begin = to_transform3f(T_odom_ref.inverse() * T_odom_begin);
  motion.rotation_vector = to_vec3f(rotation_vector);
  motion.translation_m = to_vec3f(translation);
  motion.begin_s = static_cast<float>(begin_s);
  motion.inverse_duration_per_s = static_cast<float>(1.0 / (end_s - begin_s));
  return motion;
}

}  // namespace covox::integrators

#pragma once
// De-skewing a LiDAR sweep: the sensor moved while it fired its columns, so each point was
// measured from its own pose. SweepMotion holds that motion relative to the sensor frame at the
// cloud's reference time (its stamp), and `deskew` moves a point measured `time_s` after the
// reference into that frame:
//   T_ref_sensor(t) = T_ref_begin * [exp(alpha * rotation_vector), alpha * translation],
//   alpha = (t - begin_s) / (end_s - begin_s), clamped to [0, 1],
// the begin -> end motion (in the begin frame) followed at a constant rate: translation linear in
// time, rotation along the shortest arc (Rodrigues). A non-finite time gives a non-finite point,
// which the integrator then drops and counts like any non-finite point. Usable in kernels.
#include <Eigen/Geometry>

#include "covoxslam/core/macros.h"
#include "covoxslam/core/vec3.h"

namespace covox::integrators {

struct SweepMotion {
  Transform3f T_ref_begin;  // the sensor at begin_s, seen from the reference frame
  Vec3f rotation_vector;    // begin -> end rotation in the begin frame: axis times angle (rad)
  Vec3f translation_m;      // begin -> end translation in the begin frame
  float begin_s = 0.0f;     // seconds after the reference time
  float inverse_duration_per_s = 0.0f;  // 1 / (end_s - begin_s)

  COVOX_HD_INLINE Vec3f deskew(const Vec3f& p, float time_s) const {
    float alpha = (time_s - begin_s) * inverse_duration_per_s;
    alpha = alpha < 0.0f ? 0.0f : (alpha > 1.0f ? 1.0f : alpha);  // NaN stays NaN
    const Vec3f rotated = rotate_by(rotation_vector * alpha, p);
    return T_ref_begin * (rotated + translation_m * alpha);
  }

  // p rotated by the rotation vector w (angle |w| about w / |w|).
  COVOX_HD_INLINE static Vec3f rotate_by(const Vec3f& w, const Vec3f& p) {
    const float angle = w.norm();
    if (angle < 1e-6f) {  // first order: p + w x p
      return p + cross(w, p);
    }
    const Vec3f axis = w * (1.0f / angle);
    const float c = cosf(angle), s = sinf(angle);
    return p * c + cross(axis, p) * s + axis * (axis.dot(p) * (1.0f - c));
  }
  COVOX_HD_INLINE static Vec3f cross(const Vec3f& a, const Vec3f& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
  }
};

// The motion from three odometry poses of the sensor: at the reference time, at begin_s and at
// end_s (seconds after the reference time; end_s > begin_s). Throws covox::Error for non-finite
// poses or times, or end_s <= begin_s.
SweepMotion make_sweep_motion(const Eigen::Isometry3d& T_odom_ref,
                              const Eigen::Isometry3d& T_odom_begin,
                              const Eigen::Isometry3d& T_odom_end, double begin_s, double end_s);

}  // namespace covox::integrators

#pragma once
// Turning the numbers of a pose file into a rigid transform. Real pose files are imperfect:
// printed with 6-8 digits, or accumulated by an odometry that never re-normalised, so their
// rotations are slightly off SO(3). Those are repaired (projected onto the nearest rotation) and
// counted; only poses that cannot be a rotation at all are rejected.
#include <Eigen/Geometry>

#include <string>

#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {

struct PoseTolerances {
  // max |R^T R - I| above which the rotation is re-orthonormalised and counted. 1e-5 is above
  // what printing 6 significant digits explains (KITTI-style files reach ~1.3e-6), so only poses
  // that were really off get counted; 7-Scenes' KinectFusion poses are off by ~1.5e-4.
  double reorthonormalize_above_error = 1e-5;
  // max |R^T R - I| (or |‖q‖ - 1|) above which the pose is rejected as not a rotation.
  double reject_above_error = 0.1;
};

// max over entries of |R^T R - I|: 0 for a rotation, ~|scale - 1| for a scaled one.
double orthonormality_error(const Eigen::Matrix3d& rotation);

// The rotation closest to `matrix` in the Frobenius norm (polar decomposition via SVD).
Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& matrix);

// Checks and, where needed, repairs a rotation + translation. `where` ("file:line") goes into
// the error message. Throws covox::Error for non-finite values, det(R) <= 0 or an
// orthonormality error above the reject tolerance.
Eigen::Isometry3d make_rigid_pose(const Eigen::Matrix3d& rotation,
                                  const Eigen::Vector3d& translation, const std::string& where,
                                  ReadStats* stats,
                                  const PoseTolerances& tolerances = PoseTolerances());

// As make_rigid_pose for a homogeneous 4x4 matrix, whose bottom row must be (0, 0, 0, 1).
Eigen::Isometry3d make_rigid_pose(const Eigen::Matrix4d& matrix, const std::string& where,
                                  ReadStats* stats,
                                  const PoseTolerances& tolerances = PoseTolerances());

// As make_rigid_pose for a translation and a quaternion (x, y, z, w as the files write it),
// which is always normalised; a norm off by more than the re-orthonormalise tolerance counts.
Eigen::Isometry3d make_rigid_pose_from_quaternion(
    const Eigen::Vector3d& translation, double qx, double qy, double qz, double qw,
    const std::string& where, ReadStats* stats,
    const PoseTolerances& tolerances = PoseTolerances());

}  // namespace io
}  // namespace covox

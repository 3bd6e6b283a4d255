#pragma once
// Constraints given to the SLAM system from outside (loop closures, GNSS positions, heights):
// checking them, and turning a 6-DoF loop closure between two scans into a 4-DoF constraint
// between the submaps that hold those scans.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>

#include "covoxslam/backend/pose_graph_types.h"

namespace covox {
namespace pipeline {

// voxgraph's LoopClosure: the pose of the sensor at to_stamp_s in the sensor frame at
// from_stamp_s, information over (x, y, z, roll, pitch, yaw) as in voxgraph_msgs/LoopClosure.
// Convention of the information (documented choice): the perturbed transform is
// (t + dt, Exp(dtheta) R), dt and dtheta both in the `from` sensor frame, i.e. a covariance in the
// parent frame with rotations about its fixed axes, as ROS' PoseWithCovariance.
struct LoopClosure {
  double from_stamp_s = 0;
  double to_stamp_s = 0;
  Eigen::Isometry3d T_from_to = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Identity();
};

// Empty when `information` is finite, symmetric (to 1e-9 relative) and positive semi-definite
// with at least one positive eigenvalue; otherwise what is wrong, for the log.
std::string information_problem(const Eigen::MatrixXd& information);

// Empty when the loop closure can be used; otherwise what is wrong (non-finite stamps, a
// transform that is not a finite rigid one, bad information).
std::string loop_closure_problem(const LoopClosure& closure);

struct RelativeConstraint4Dof {
  backend::Pose4Dof measurement;  // T_Sa_Sb as (dx, dy, dz in Sa, dyaw)
  Eigen::Matrix4d information = Eigen::Matrix4d::Zero();
};

// The loop closure as a constraint between the gravity-aligned submap frames Sa (holding the
// `from` scan, at T_Sa_from) and Sb (holding the `to` scan, at T_Sb_to):
//   T_Sa_Sb = T_Sa_from * T_from_to * T_Sb_to^-1,  measurement (t(T_Sa_Sb), yaw(T_Sa_Sb)).
// Information, to first order: perturbing T_from_to by (dt, dtheta) (convention above) perturbs
// T_Sa_Sb by (e_t, e_theta) in Sa, with e_theta = R_a dtheta and
// e_t = R_a dt - R_a [R_ft t_b]x dtheta, where R_a = R(T_Sa_from), R_ft = R(T_from_to) and
// t_b = t(T_Sb_to^-1): e = K d with K invertible, so the information of e is K^-T L K^-1. The
// graph's 4-DoF residual sees (e_t, e_theta_z) (yaw of a gravity-aligned relative pose);
// roll and pitch (e_theta_x, e_theta_y) are nuisance and marginalised out with the Schur
// complement  L_44 = L_ww - L_wn L_nn^+ L_nw  (pseudo-inverse: they may carry no information).
RelativeConstraint4Dof project_loop_closure(const Eigen::Isometry3d& T_Sa_from,
                                            const Eigen::Isometry3d& T_from_to,
                                            const Eigen::Isometry3d& T_Sb_to,
                                            const Eigen::Matrix<double, 6, 6>& information);

}  // namespace pipeline
}  // namespace covox

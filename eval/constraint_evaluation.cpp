#include "eval/constraint_evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "covoxslam/pipeline/submap.h"
#include "eval/trajectory_evaluation.h"

namespace covox {
namespace eval {

namespace {

constexpr double kPi = 3.14159265358979323846;

struct SubmapPoses {
  backend::Pose4Dof reference;
  backend::Pose4Dof odometry;
};

// Each submap's reference pose (at its first stamp, gravity aligned) and odometry pose, by id;
// submaps whose stamp the reference does not cover are left out.
std::map<int64_t, SubmapPoses> submap_poses(const io::Trajectory& reference,
                                            const std::vector<pipeline::SubmapInfo>& submaps) {
  std::map<int64_t, SubmapPoses> poses;
  for (const pipeline::SubmapInfo& submap : submaps) {
    io::StampedPose pose;
    if (submap.loaded || !interpolate_pose(reference, submap.statistics.start_stamp_s, &pose))
      continue;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = pose.orientation.normalized().toRotationMatrix();
    T.translation() = pose.position_m;
    poses[submap.id] = SubmapPoses{pipeline::pose_4dof_from_isometry(T),
                                   pipeline::pose_4dof_from_isometry(submap.T_odom_submap)};
  }
  return poses;
}

void difference(const backend::Pose4Dof& a, const backend::Pose4Dof& b, double* metres,
                double* radians) {
  *metres =
      std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) + (a.z - b.z) * (a.z - b.z));
  *radians = std::abs(std::remainder(a.yaw - b.yaw, 2.0 * kPi));
}

}  // namespace

ConstraintEvaluation evaluate_registration_constraints(
    const io::Trajectory& reference, const std::vector<pipeline::SubmapInfo>& submaps,
    const std::vector<pipeline::SubmapConstraint>& constraints, double tolerance_m,
    double tolerance_yaw_rad) {
  ConstraintEvaluation evaluation;
  const std::map<int64_t, SubmapPoses> poses = submap_poses(reference, submaps);
  for (const pipeline::SubmapConstraint& c : constraints) {
    if (c.kind != pipeline::SubmapConstraintKind::kRegistration) continue;
    const auto from = poses.find(c.from_submap);
    const auto to = poses.find(c.to_submap);
    if (from == poses.end() || to == poses.end()) {
      ++evaluation.unevaluated;
      continue;
    }
    ConstraintError e;
    e.from_submap = c.from_submap;
    e.to_submap = c.to_submap;
    e.active = c.active;
    const backend::Pose4Dof truth =
        pipeline::relative_pose_4dof(from->second.reference, to->second.reference);
    const backend::Pose4Dof odometry =
        pipeline::relative_pose_4dof(from->second.odometry, to->second.odometry);
    difference(c.measurement, truth, &e.error_m, &e.error_yaw_rad);
    difference(odometry, truth, &e.odometry_error_m, &e.odometry_error_yaw_rad);
    evaluation.max_error_m = std::max(evaluation.max_error_m, e.error_m);
    evaluation.max_error_yaw_rad = std::max(evaluation.max_error_yaw_rad, e.error_yaw_rad);
    if (e.error_m > tolerance_m || e.error_yaw_rad > tolerance_yaw_rad) ++evaluation.wrong;
    e.from_place_recognition = c.from_place_recognition;
    if (c.from_place_recognition) {
      ++evaluation.closures;
      evaluation.max_closure_error_m = std::max(evaluation.max_closure_error_m, e.error_m);
      if (e.error_m > kWrongClosureM || e.error_yaw_rad > kWrongClosureRad) {
        ++evaluation.wrong_closures;
      }
    }
    evaluation.constraints.push_back(e);
  }
  return evaluation;
}

void print_constraint_evaluation(const ConstraintEvaluation& evaluation, FILE* out) {
  std::fprintf(out, "registration constraints against the reference:\n");
  std::fprintf(out, "  %5s %5s %6s %10s %10s %12s %12s %s\n", "from", "to", "active", "error_m",
               "error_deg", "odom_err_m", "odom_err_deg", "found by");
  for (const ConstraintError& e : evaluation.constraints) {
    std::fprintf(out, "  %5lld %5lld %6s %10.4f %10.3f %12.4f %12.3f %s\n",
                 static_cast<long long>(e.from_submap), static_cast<long long>(e.to_submap),
                 e.active ? "yes" : "no", e.error_m, e.error_yaw_rad * 180.0 / kPi,
                 e.odometry_error_m, e.odometry_error_yaw_rad * 180.0 / kPi,
                 e.from_place_recognition ? "place recognition" : "overlap");
  }
  std::fprintf(out,
               "  %zu evaluated (%lld without reference): max error %.4f m, %.3f deg; %lld beyond "
               "the tolerance\n",
               evaluation.constraints.size(), static_cast<long long>(evaluation.unevaluated),
               evaluation.max_error_m, evaluation.max_error_yaw_rad * 180.0 / kPi,
               static_cast<long long>(evaluation.wrong));
  print_closure_evaluation(evaluation, out);
}

void print_closure_evaluation(const ConstraintEvaluation& evaluation, FILE* out) {
  std::fprintf(out,
               "place-recognition closures against the reference: %lld, %lld wrong by more than "
               "%.1f m or %.0f deg (max error %.3f m)\n",
               static_cast<long long>(evaluation.closures),
               static_cast<long long>(evaluation.wrong_closures), kWrongClosureM,
               kWrongClosureRad * 180.0 / kPi, evaluation.max_closure_error_m);
}

}  // namespace eval
}  // namespace covox

#pragma once
// Registration constraints against the reference: for every registration constraint of a run's
// final pose graph, the error of its measured relative pose against the reference relative pose
// of its two submaps, and the odometry's error for the same pair.
//
// A submap's frame is the gravity-aligned pose of its first scan's sensor (pipeline/submap.h), so
// its reference pose is the reference trajectory interpolated at the submap's first stamp, gravity
// aligned; the relative pose of two such poses is frame-free, so the reference and the odometry
// need not share a world frame.
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace tools {

struct ConstraintError {
  int64_t from_submap = -1;
  int64_t to_submap = -1;
  bool active = true;             // false: set aside by the consistency gate
  double error_m = 0.0;           // |measured - reference| over x, y, z
  double error_yaw_rad = 0.0;     // wrapped
  double odometry_error_m = 0.0;  // the odometry's relative pose against the reference
  double odometry_error_yaw_rad = 0.0;
};

struct ConstraintEvaluation {
  std::vector<ConstraintError> constraints;  // registration constraints with a reference
  int64_t unevaluated = 0;                   // a submap stamp outside the reference
  double max_error_m = 0.0;
  double max_error_yaw_rad = 0.0;
  // Constraints wrong by more than the tolerances given to evaluate_registration_constraints.
  int64_t wrong = 0;
};

ConstraintEvaluation evaluate_registration_constraints(
    const io::Trajectory& reference, const std::vector<pipeline::SubmapInfo>& submaps,
    const std::vector<pipeline::SubmapConstraint>& constraints, double tolerance_m,
    double tolerance_yaw_rad);

// One line per constraint and a summary line.
void print_constraint_evaluation(const ConstraintEvaluation& evaluation, FILE* out);

}  // namespace tools
}  // namespace covox

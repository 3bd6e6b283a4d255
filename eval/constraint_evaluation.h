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
namespace eval {

struct ConstraintError {
  int64_t from_submap = -1;
  int64_t to_submap = -1;
  bool active = true;  // false: set aside by the consistency gate
  bool from_place_recognition = false;
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
  // Of them, the loop closures of place recognition: how many, and how many are a wrong place
  // (further than kWrongClosureM or kWrongClosureRad from the reference, whatever the
  // registration tolerances).
  int64_t closures = 0;
  int64_t wrong_closures = 0;
  double max_closure_error_m = 0.0;
};

// A loop closure this far from the reference relative pose joins two different places (or the
// right place at an error that bends the map): several voxels and degrees, far beyond a right
// registration's error.
constexpr double kWrongClosureM = 1.0;
constexpr double kWrongClosureRad = 5.0 * 3.14159265358979323846 / 180.0;

ConstraintEvaluation evaluate_registration_constraints(
    const io::Trajectory& reference, const std::vector<pipeline::SubmapInfo>& submaps,
    const std::vector<pipeline::SubmapConstraint>& constraints, double tolerance_m,
    double tolerance_yaw_rad);

// One line per constraint and the summary lines.
void print_constraint_evaluation(const ConstraintEvaluation& evaluation, FILE* out);
// The place-recognition closures' summary line.
void print_closure_evaluation(const ConstraintEvaluation& evaluation, FILE* out);

}  // namespace eval
}  // namespace covox

#pragma once
// Trajectory accuracy the way the ARCHE evaluation measures it: the estimate is interpolated at
// the reference (ground-truth) timestamps, aligned to the reference, and the remaining position
// error is summarised (ATE). The relative pose error (RPE) measures drift over a fixed distance or
// number of frames, independently of where the trajectory started.
//
// Alignment uses positions only, so position-only ground truth (RTK fixes) works with every mode.
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/io/trajectory_io.h"

namespace covox {
namespace eval {

// ---------------------------------------------------------------------------------------------
// Association: the estimate sampled at reference timestamps.
// ---------------------------------------------------------------------------------------------

struct AssociationOptions {
  // A reference stamp is used only if an estimate pose lies within this time of it: interpolating
  // across a longer hole in the estimate would invent motion. This is the tolerance TUM's
  // associate.py calls max_difference.
  double max_time_gap_s = 0.1;
};

struct AssociatedTrajectories {
  std::vector<double> timestamps_s;
  std::vector<Eigen::Vector3d> reference_positions_m;
  std::vector<Eigen::Quaterniond> reference_orientations;
  std::vector<Eigen::Vector3d> estimate_positions_m;
  std::vector<Eigen::Quaterniond> estimate_orientations;
  // Rotational errors need orientations on both sides.
  bool has_orientations = false;
  // Reference stamps before the estimate's first or after its last pose.
  size_t skipped_outside_range = 0;
  // Reference stamps inside the range but farther than max_time_gap_s from any estimate pose.
  size_t skipped_time_gap = 0;

  size_t size() const { return timestamps_s.size(); }
};

// Linear interpolation of positions and slerp of orientations between the two estimate poses
// bracketing each reference stamp.
AssociatedTrajectories associate_by_interpolation(const io::Trajectory& reference,
                                                  const io::Trajectory& estimate,
                                                  const AssociationOptions& options);

// The estimate pose at `timestamp_s`, interpolated; false when the stamp lies outside the
// estimate's time range.
bool interpolate_pose(const io::Trajectory& trajectory, double timestamp_s, io::StampedPose* pose);

// ---------------------------------------------------------------------------------------------
// Alignment: the transform that maps the estimate onto the reference (least squares).
// ---------------------------------------------------------------------------------------------

enum class AlignmentMode {
  kNone,            // compare in the frames as given
  kTranslation,     // 3 DoF: removes a constant offset
  kTranslationYaw,  // 4 DoF: x, y, z, yaw - what gravity-aligned odometry can drift in
  kSe3,             // 6 DoF rigid (Umeyama without scale)
  kSim3,            // 7 DoF similarity (Umeyama with scale), for monocular-style scale drift
};

// Accepts "none", "translation", "4dof", "se3", "sim3"; throws covox::Error listing them otherwise.
AlignmentMode parse_alignment_mode(const std::string& text);
std::string alignment_mode_name(AlignmentMode mode);
// Fewest point pairs that determine the transform of `mode`.
size_t minimum_points_for_alignment(AlignmentMode mode);

// p_aligned = scale * rotation * p + translation_m.
struct SimilarityTransform {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation_m = Eigen::Vector3d::Zero();
  double scale = 1.0;

  Eigen::Vector3d apply(const Eigen::Vector3d& point) const {
    return scale * (rotation * point) + translation_m;
  }
};

// The transform minimising sum |T(source_i) - target_i|^2 within `mode`. Throws covox::Error when
// the sizes differ or there are fewer pairs than the mode needs.
SimilarityTransform estimate_alignment(const std::vector<Eigen::Vector3d>& source_m,
                                       const std::vector<Eigen::Vector3d>& target_m,
                                       AlignmentMode mode);

// ---------------------------------------------------------------------------------------------
// Statistics and the full evaluation.
// ---------------------------------------------------------------------------------------------

struct ErrorStatistics {
  size_t count = 0;
  double rmse = 0.0;
  double mean = 0.0;
  double median = 0.0;
  double max = 0.0;
};

// All zero for an empty input.
ErrorStatistics compute_error_statistics(std::vector<double> values);

enum class RelativeDeltaUnit { kMetres, kFrames };

struct RelativePoseErrorOptions {
  // Pairs (i, j) where j is the first associated pose at least `delta` after i: metres travelled
  // along the reference, or frames (associated poses).
  double delta = 1.0;
  RelativeDeltaUnit unit = RelativeDeltaUnit::kMetres;
};

// Accepts "m" / "metres" / "meters" and "frames".
RelativeDeltaUnit parse_relative_delta_unit(const std::string& text);

struct RelativePoseError {
  // One entry per pair.
  std::vector<double> translation_errors_m;
  std::vector<double> rotation_errors_deg;  // empty without orientations
  ErrorStatistics translation_m;
  ErrorStatistics rotation_deg;
  bool has_rotation = false;
};

// With orientations on both sides: the translation and angle of (Q_i^-1 Q_j)^-1 (P_i^-1 P_j),
// reference Q, estimate P (the TUM/KITTI definition). Position-only: the difference of the
// displacement vectors p_j - p_i in the (aligned) world frame, and no rotation error.
RelativePoseError compute_relative_pose_error(const AssociatedTrajectories& associated,
                                              const RelativePoseErrorOptions& options);

struct TrajectoryEvaluationOptions {
  AssociationOptions association;
  AlignmentMode alignment = AlignmentMode::kTranslationYaw;
  RelativePoseErrorOptions relative;
};

struct TrajectoryEvaluation {
  size_t reference_poses = 0;
  size_t estimate_poses = 0;
  // After alignment: the estimate positions and orientations are mapped into the reference frame
  // (and scale, for sim3).
  AssociatedTrajectories aligned;
  SimilarityTransform alignment;
  // Absolute trajectory error: |reference_i - aligned estimate_i| per associated stamp.
  std::vector<double> position_errors_m;
  ErrorStatistics absolute_position_m;
  RelativePoseError relative;
};

// Throws covox::Error when fewer poses associate than the alignment needs (the message says how
// many stamps were outside the estimate's range or beyond the time gap, which is what to fix).
TrajectoryEvaluation evaluate_trajectory(const io::Trajectory& reference,
                                         const io::Trajectory& estimate,
                                         const TrajectoryEvaluationOptions& options);

}  // namespace eval
}  // namespace covox

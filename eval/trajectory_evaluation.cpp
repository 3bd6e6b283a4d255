#include "eval/trajectory_evaluation.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <Eigen/SVD>

#include "covoxslam/core/error.h"

namespace covox {
namespace eval {
namespace {

constexpr double kRadiansToDegrees = 180.0 / 3.14159265358979323846;

// Index of the first pose with a timestamp >= timestamp_s (poses.size() when there is none).
size_t first_pose_not_before(const io::Trajectory& trajectory, double timestamp_s) {
  const auto it = std::lower_bound(
      trajectory.poses.begin(), trajectory.poses.end(), timestamp_s,
      [](const io::StampedPose& pose, double stamp) { return pose.timestamp_s < stamp; });
  return static_cast<size_t>(it - trajectory.poses.begin());
}

io::StampedPose interpolate_between(const io::StampedPose& before, const io::StampedPose& after,
                                    double timestamp_s) {
  const double fraction =
      (timestamp_s - before.timestamp_s) / (after.timestamp_s - before.timestamp_s);
  io::StampedPose pose;
  pose.timestamp_s = timestamp_s;
  pose.position_m = before.position_m + fraction * (after.position_m - before.position_m);
  // Eigen's slerp takes the shorter arc, so q and -q neighbours do not spin the long way round.
  pose.orientation = before.orientation.slerp(fraction, after.orientation).normalized();
  return pose;
}

Eigen::Vector3d centroid(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) sum += p;
  return sum / static_cast<double>(points.size());
}

// Closed form 4-DoF fit: after centring, the yaw maximising sum t_i . R(yaw) s_i in the xy plane
// is atan2 of the antisymmetric and symmetric parts of the 2-D cross-covariance.
SimilarityTransform align_translation_yaw(const std::vector<Eigen::Vector3d>& source,
                                          const std::vector<Eigen::Vector3d>& target) {
  const Eigen::Vector3d source_centre = centroid(source);
  const Eigen::Vector3d target_centre = centroid(target);
  double cross_sum = 0.0;  // sum (s_x t_y - s_y t_x)
  double dot_sum = 0.0;    // sum (s_x t_x + s_y t_y)
  for (size_t i = 0; i < source.size(); ++i) {
    const Eigen::Vector3d s = source[i] - source_centre;
    const Eigen::Vector3d t = target[i] - target_centre;
    cross_sum += s.x() * t.y() - s.y() * t.x();
    dot_sum += s.x() * t.x() + s.y() * t.y();
  }
  const double yaw_rad = std::atan2(cross_sum, dot_sum);
  SimilarityTransform transform;
  transform.rotation = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  transform.translation_m = target_centre - transform.rotation * source_centre;
  return transform;
}

// Umeyama (1991): rotation from the SVD of the cross-covariance, with the sign fix that keeps it
// a rotation rather than a reflection; scale from the singular values over the source variance.
SimilarityTransform align_umeyama(const std::vector<Eigen::Vector3d>& source,
                                  const std::vector<Eigen::Vector3d>& target, bool with_scale) {
  const Eigen::Vector3d source_centre = centroid(source);
  const Eigen::Vector3d target_centre = centroid(target);
  const double count = static_cast<double>(source.size());
  Eigen::Matrix3d cross_covariance = Eigen::Matrix3d::Zero();
  double source_variance = 0.0;
  for (size_t i = 0; i < source.size(); ++i) {
    const Eigen::Vector3d s = source[i] - source_centre;
    cross_covariance += (target[i] - target_centre) * s.transpose();
    source_variance += s.squaredNorm();
  }
  cross_covariance /= count;
  source_variance /= count;
  if (source_variance <= 0.0) {
    throw Error(
        "trajectory alignment: all estimate positions are identical; se3/sim3 alignment "
        "needs motion (use --align translation or none)");
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cross_covariance,
                                        Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d sign_fix(1.0, 1.0, 1.0);
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) sign_fix.z() = -1.0;
  SimilarityTransform transform;
  transform.rotation = svd.matrixU() * sign_fix.asDiagonal() * svd.matrixV().transpose();
  transform.scale = with_scale ? svd.singularValues().dot(sign_fix) / source_variance : 1.0;
  transform.translation_m = target_centre - transform.scale * transform.rotation * source_centre;
  return transform;
}

double rotation_angle_deg(const Eigen::Quaterniond& q) {
  // atan2 form stays accurate for the tiny angles drift produces, unlike acos(w).
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w())) * kRadiansToDegrees;
}

// Cumulative distance travelled along the reference at each associated pose.
std::vector<double> distance_travelled_m(const std::vector<Eigen::Vector3d>& positions) {
  std::vector<double> travelled(positions.size(), 0.0);
  for (size_t i = 1; i < positions.size(); ++i) {
    travelled[i] = travelled[i - 1] + (positions[i] - positions[i - 1]).norm();
  }
  return travelled;
}

}  // namespace

bool interpolate_pose(const io::Trajectory& trajectory, double timestamp_s, io::StampedPose* pose) {
  const size_t after = first_pose_not_before(trajectory, timestamp_s);
  if (after == trajectory.size()) return false;
  if (trajectory.poses[after].timestamp_s == timestamp_s) {
    *pose = trajectory.poses[after];
    return true;
  }
  if (after == 0) return false;
  *pose = interpolate_between(trajectory.poses[after - 1], trajectory.poses[after], timestamp_s);
  return true;
}

AssociatedTrajectories associate_by_interpolation(const io::Trajectory& reference,
                                                  const io::Trajectory& estimate,
                                                  const AssociationOptions& options) {
  if (!(options.max_time_gap_s > 0.0)) {
    throw Error("trajectory association: max_time_gap_s must be positive, got " +
                std::to_string(options.max_time_gap_s));
  }
  AssociatedTrajectories associated;
  associated.has_orientations = reference.has_orientations && estimate.has_orientations;
  for (const io::StampedPose& reference_pose : reference.poses) {
    const double stamp = reference_pose.timestamp_s;
    const size_t after = first_pose_not_before(estimate, stamp);
    const bool exact = after < estimate.size() && estimate.poses[after].timestamp_s == stamp;
    if (!exact && (after == 0 || after == estimate.size())) {
      ++associated.skipped_outside_range;
      continue;
    }
    io::StampedPose estimate_pose;
    if (exact) {
      estimate_pose = estimate.poses[after];
    } else {
      const io::StampedPose& before = estimate.poses[after - 1];
      const io::StampedPose& next = estimate.poses[after];
      const double nearest_gap_s = std::min(stamp - before.timestamp_s, next.timestamp_s - stamp);
      if (nearest_gap_s > options.max_time_gap_s) {
        ++associated.skipped_time_gap;
        continue;
      }
      estimate_pose = interpolate_between(before, next, stamp);
    }
    associated.timestamps_s.push_back(stamp);
    associated.reference_positions_m.push_back(reference_pose.position_m);
    associated.reference_orientations.push_back(reference_pose.orientation);
    associated.estimate_positions_m.push_back(estimate_pose.position_m);
    associated.estimate_orientations.push_back(estimate_pose.orientation);
  }
  return associated;
}

AlignmentMode parse_alignment_mode(const std::string& text) {
  if (text == "none") return AlignmentMode::kNone;
  if (text == "translation") return AlignmentMode::kTranslation;
  if (text == "4dof" || text == "translation_yaw") return AlignmentMode::kTranslationYaw;
  if (text == "se3") return AlignmentMode::kSe3;
  if (text == "sim3") return AlignmentMode::kSim3;
  throw Error("unknown alignment '" + text + "': use none, translation, 4dof, se3 or sim3");
}

std::string alignment_mode_name(AlignmentMode mode) {
  switch (mode) {
    case AlignmentMode::kNone:
      return "none";
    case AlignmentMode::kTranslation:
      return "translation";
    case AlignmentMode::kTranslationYaw:
      return "4dof";
    case AlignmentMode::kSe3:
      return "se3";
    case AlignmentMode::kSim3:
      return "sim3";
  }
  return "unknown";
}

size_t minimum_points_for_alignment(AlignmentMode mode) {
  switch (mode) {
    case AlignmentMode::kNone:
    case AlignmentMode::kTranslation:
      return 1;
    case AlignmentMode::kTranslationYaw:
      return 2;
    case AlignmentMode::kSe3:
    case AlignmentMode::kSim3:
      return 3;
  }
  return 3;
}

SimilarityTransform estimate_alignment(const std::vector<Eigen::Vector3d>& source_m,
                                       const std::vector<Eigen::Vector3d>& target_m,
                                       AlignmentMode mode) {
  if (source_m.size() != target_m.size()) {
    throw Error("trajectory alignment: " + std::to_string(source_m.size()) + " estimate but " +
                std::to_string(target_m.size()) + " reference positions");
  }
  const size_t needed = minimum_points_for_alignment(mode);
  if (source_m.size() < needed) {
    throw Error("trajectory alignment '" + alignment_mode_name(mode) + "' needs at least " +
                std::to_string(needed) + " associated poses, got " +
                std::to_string(source_m.size()));
  }
  switch (mode) {
    case AlignmentMode::kNone:
      return SimilarityTransform();
    case AlignmentMode::kTranslation: {
      SimilarityTransform transform;
      transform.translation_m = centroid(target_m) - centroid(source_m);
      return transform;
    }
    case AlignmentMode::kTranslationYaw:
      return align_translation_yaw(source_m, target_m);
    case AlignmentMode::kSe3:
      return align_umeyama(source_m, target_m, false);
    case AlignmentMode::kSim3:
      return align_umeyama(source_m, target_m, true);
  }
  return SimilarityTransform();
}

ErrorStatistics compute_error_statistics(std::vector<double> values) {
  ErrorStatistics statistics;
  statistics.count = values.size();
  if (values.empty()) return statistics;
  double sum = 0.0;
  double sum_of_squares = 0.0;
  for (double value : values) {
    sum += value;
    sum_of_squares += value * value;
    statistics.max = std::max(statistics.max, value);
  }
  const double count = static_cast<double>(values.size());
  statistics.mean = sum / count;
  statistics.rmse = std::sqrt(sum_of_squares / count);
  const size_t middle = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + middle, values.end());
  statistics.median = values[middle];
  if (values.size() % 2 == 0) {
    // The lower middle is the largest of the lower half, which nth_element left unsorted.
    const double lower_middle = *std::max_element(values.begin(), values.begin() + middle);
    statistics.median = 0.5 * (statistics.median + lower_middle);
  }
  return statistics;
}

RelativeDeltaUnit parse_relative_delta_unit(const std::string& text) {
  if (text == "m" || text == "metres" || text == "meters") return RelativeDeltaUnit::kMetres;
  if (text == "frames") return RelativeDeltaUnit::kFrames;
  throw Error("unknown RPE delta unit '" + text + "': use m or frames");
}

RelativePoseError compute_relative_pose_error(const AssociatedTrajectories& associated,
                                              const RelativePoseErrorOptions& options) {
  if (!(options.delta > 0.0)) {
    throw Error("relative pose error: delta must be positive, got " +
                std::to_string(options.delta));
  }
  const bool in_frames = options.unit == RelativeDeltaUnit::kFrames;
  if (in_frames && options.delta != std::floor(options.delta)) {
    throw Error("relative pose error: a delta in frames must be a whole number, got " +
                std::to_string(options.delta));
  }
  RelativePoseError result;
  result.has_rotation = associated.has_orientations;
  const size_t count = associated.size();
  const std::vector<double> travelled = distance_travelled_m(associated.reference_positions_m);
  for (size_t i = 0; i < count; ++i) {
    size_t j = 0;
    if (in_frames) {
      j = i + static_cast<size_t>(options.delta);
    } else {
      j = static_cast<size_t>(
          std::lower_bound(travelled.begin() + i, travelled.end(), travelled[i] + options.delta) -
          travelled.begin());
    }
    if (j >= count) break;  // every later i would also run past the end

    const Eigen::Vector3d& ref_i = associated.reference_positions_m[i];
    const Eigen::Vector3d& ref_j = associated.reference_positions_m[j];
    const Eigen::Vector3d& est_i = associated.estimate_positions_m[i];
    const Eigen::Vector3d& est_j = associated.estimate_positions_m[j];
    if (!associated.has_orientations) {
      result.translation_errors_m.push_back(((est_j - est_i) - (ref_j - ref_i)).norm());
      continue;
    }
    const Eigen::Quaterniond& ref_qi = associated.reference_orientations[i];
    const Eigen::Quaterniond& ref_qj = associated.reference_orientations[j];
    const Eigen::Quaterniond& est_qi = associated.estimate_orientations[i];
    const Eigen::Quaterniond& est_qj = associated.estimate_orientations[j];
    // Relative motions expressed in the frame of pose i, then their discrepancy.
    const Eigen::Quaterniond ref_relative_q = ref_qi.conjugate() * ref_qj;
    const Eigen::Vector3d ref_relative_t = ref_qi.conjugate() * (ref_j - ref_i);
    const Eigen::Quaterniond est_relative_q = est_qi.conjugate() * est_qj;
    const Eigen::Vector3d est_relative_t = est_qi.conjugate() * (est_j - est_i);
    const Eigen::Quaterniond error_q = ref_relative_q.conjugate() * est_relative_q;
    const Eigen::Vector3d error_t = ref_relative_q.conjugate() * (est_relative_t - ref_relative_t);
    result.translation_errors_m.push_back(error_t.norm());
    result.rotation_errors_deg.push_back(rotation_angle_deg(error_q));
  }
  result.translation_m = compute_error_statistics(result.translation_errors_m);
  result.rotation_deg = compute_error_statistics(result.rotation_errors_deg);
  return result;
}

TrajectoryEvaluation evaluate_trajectory(const io::Trajectory& reference,
                                         const io::Trajectory& estimate,
                                         const TrajectoryEvaluationOptions& options) {
  TrajectoryEvaluation evaluation;
  evaluation.reference_poses = reference.size();
  evaluation.estimate_poses = estimate.size();
  evaluation.aligned = associate_by_interpolation(reference, estimate, options.association);
  AssociatedTrajectories& aligned = evaluation.aligned;

  const size_t needed = minimum_points_for_alignment(options.alignment);
  if (aligned.size() < needed) {
    throw Error("trajectory evaluation: only " + std::to_string(aligned.size()) + " of " +
                std::to_string(reference.size()) + " reference stamps matched the estimate (" +
                std::to_string(aligned.skipped_outside_range) + " outside its time range, " +
                std::to_string(aligned.skipped_time_gap) +
                " farther than the max time gap from any estimate pose); alignment '" +
                alignment_mode_name(options.alignment) + "' needs " + std::to_string(needed) +
                ". Check that both files use the same clock, or raise the max time gap.");
  }

  evaluation.alignment = estimate_alignment(aligned.estimate_positions_m,
                                            aligned.reference_positions_m, options.alignment);
  const Eigen::Quaterniond alignment_rotation(evaluation.alignment.rotation);
  for (size_t i = 0; i < aligned.size(); ++i) {
    aligned.estimate_positions_m[i] = evaluation.alignment.apply(aligned.estimate_positions_m[i]);
    aligned.estimate_orientations[i] = alignment_rotation * aligned.estimate_orientations[i];
    evaluation.position_errors_m.push_back(
        (aligned.estimate_positions_m[i] - aligned.reference_positions_m[i]).norm());
  }
  evaluation.absolute_position_m = compute_error_statistics(evaluation.position_errors_m);
  evaluation.relative = compute_relative_pose_error(aligned, options.relative);
  return evaluation;
}

}  // namespace eval
}  // namespace covox

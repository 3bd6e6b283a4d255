#include "covoxslam/backend/synthetic_pose_graph.h"

#include <cmath>
#include <random>

#include "covoxslam/core/error.h"

namespace covox {
namespace backend {
namespace {

constexpr double kPi = 3.14159265358979323846;

// The truth trajectory: a figure-of-eight of about `step_m` spacing, climbing slowly, heading
// along the direction of travel. Returns (position, yaw) per submap.
std::vector<Pose4Dof> figure_of_eight(const SyntheticGraphOptions& o) {
  std::vector<Pose4Dof> poses(static_cast<size_t>(o.submaps));
  // Radius chosen so one lap of the eight holds ~40 submaps: loops close every lap.
  const double radius = 40.0 * o.step_m / (4.0 * kPi);
  for (int k = 0; k < o.submaps; ++k) {
    const double s = 2.0 * kPi * k / 40.0;
    Pose4Dof& p = poses[k];
    p.x = radius * std::sin(s);
    p.y = radius * std::sin(s) * std::cos(s);
    p.z = 0.02 * k + 0.5 * std::sin(0.3 * k);
    const double dx = radius * std::cos(s), dy = radius * std::cos(2.0 * s);
    p.yaw = std::atan2(dy, dx);
  }
  return poses;
}

// Constraint pairs: consecutive ones, then close non-consecutive ones (nearest first).
std::vector<std::pair<int32_t, int32_t>> constraint_pairs(const std::vector<Pose4Dof>& truth,
                                                          const SyntheticGraphOptions& o) {
  std::vector<std::pair<int32_t, int32_t>> pairs;
  const int n = static_cast<int>(truth.size());
  for (int k = 0; k + 1 < n; ++k) pairs.emplace_back(k, k + 1);
  for (int i = 0; i < n; ++i) {
    int added = 0;
    for (int j = i + 2; j < n && added < o.max_loops_per_submap; ++j) {
      const double dx = truth[j].x - truth[i].x, dy = truth[j].y - truth[i].y,
                   dz = truth[j].z - truth[i].z;
      if (dx * dx + dy * dy + dz * dz < o.loop_radius_m * o.loop_radius_m) {
        pairs.emplace_back(i, j);
        ++added;
      }
    }
  }
  return pairs;
}

void check(const SyntheticGraphOptions& o) {
  if (o.submaps < 2)
    throw Error("synthetic pose graph: submaps must be at least 2, got " +
                std::to_string(o.submaps));
  if (!(o.translation_sigma_m > 0.0) || !(o.rotation_sigma_rad > 0.0)) {
    throw Error(
        "synthetic pose graph: translation_sigma_m and rotation_sigma_rad must be positive");
  }
}

Eigen::Isometry3d isometry_of(const Pose4Dof& p) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(p.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(p.x, p.y, p.z);
  return t;
}

}  // namespace

Synthetic4DofGraph make_synthetic_graph_4dof(const SyntheticGraphOptions& o) {
  check(o);
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Synthetic4DofGraph out;
  out.truth = figure_of_eight(o);
  const double st = o.translation_sigma_m, sr = o.rotation_sigma_rad;
  Eigen::Matrix4d information =
      Eigen::Vector4d(1 / (st * st), 1 / (st * st), 1 / (st * st), 1 / (sr * sr)).asDiagonal();
  for (const auto& [i, j] : constraint_pairs(out.truth, o)) {
    const Pose4Dof& a = out.truth[i];
    const Pose4Dof& b = out.truth[j];
    const double c = std::cos(a.yaw), s = std::sin(a.yaw);
    Pose4Dof z;
    z.x = c * (b.x - a.x) + s * (b.y - a.y) + st * normal(rng);
    z.y = -s * (b.x - a.x) + c * (b.y - a.y) + st * normal(rng);
    z.z = b.z - a.z + st * normal(rng);
    z.yaw = b.yaw - a.yaw + sr * normal(rng);
    out.graph.constraints.push_back(make_relative_constraint_4dof(i, j, z, information));
  }
  for (int k = 0; k < o.submaps; ++k) {
    const Pose4Dof& t = out.truth[k];
    if (o.absolute_position_every > 0 && k % o.absolute_position_every == 0) {
      const Eigen::Vector3d p(t.x + st * normal(rng), t.y + st * normal(rng),
                              t.z + st * normal(rng));
      out.graph.constraints.push_back(
          make_position_constraint_4dof(k, p, Eigen::Matrix3d::Identity() / (st * st)));
    }
    if (o.height_constraints) {
      out.graph.constraints.push_back(
          make_height_constraint_4dof(k, t.z + st * normal(rng), 1.0 / (st * st)));
    }
  }
  out.graph.poses = out.truth;
  for (int k = 1; k < o.submaps; ++k) {
    Pose4Dof& p = out.graph.poses[k];
    p.x += o.initial_translation_perturbation_m * uniform(rng);
    p.y += o.initial_translation_perturbation_m * uniform(rng);
    p.z += o.initial_translation_perturbation_m * uniform(rng);
    p.yaw += o.initial_rotation_perturbation_rad * uniform(rng);
  }
  out.graph.fixed_vertex = 0;
  return out;
}

SyntheticSe3Graph make_synthetic_graph_se3(const SyntheticGraphOptions& o) {
  check(o);
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const auto planar = figure_of_eight(o);
  SyntheticSe3Graph out;
  std::vector<Eigen::Isometry3d> truth;
  for (size_t k = 0; k < planar.size(); ++k) {
    // Add some roll and pitch so that every rotation axis is exercised.
    Eigen::Isometry3d t = isometry_of(planar[k]);
    t.linear() =
        t.linear() *
        Eigen::AngleAxisd(0.2 * std::sin(0.7 * k), Eigen::Vector3d::UnitX()).toRotationMatrix() *
        Eigen::AngleAxisd(0.15 * std::cos(0.4 * k), Eigen::Vector3d::UnitY()).toRotationMatrix();
    truth.push_back(t);
    out.truth.push_back(make_se3_pose(t.translation(), Eigen::Quaterniond(t.linear())));
  }
  const double st = o.translation_sigma_m, sr = o.rotation_sigma_rad;
  Eigen::Matrix<double, 6, 1> diagonal;
  diagonal << 1 / (st * st), 1 / (st * st), 1 / (st * st), 1 / (sr * sr), 1 / (sr * sr),
      1 / (sr * sr);
  const Eigen::Matrix<double, 6, 6> information = diagonal.asDiagonal();
  for (const auto& [i, j] : constraint_pairs(planar, o)) {
    const Eigen::Isometry3d z = truth[i].inverse() * truth[j];
    const Eigen::Vector3d dt(st * normal(rng), st * normal(rng), st * normal(rng));
    const Eigen::Vector3d dr(sr * normal(rng), sr * normal(rng), sr * normal(rng));
    const Eigen::Matrix3d rotation =
        z.linear() * Eigen::AngleAxisd(dr.norm(), dr.normalized()).toRotationMatrix();
    out.graph.constraints.push_back(make_se3_constraint(
        i, j, make_se3_pose(z.translation() + dt, Eigen::Quaterniond(rotation)), information));
  }
  out.graph.poses = out.truth;
  for (int k = 1; k < o.submaps; ++k) {
    const Eigen::Vector3d dt = o.initial_translation_perturbation_m *
                               Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
    const Eigen::Vector3d dr = o.initial_rotation_perturbation_rad *
                               Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
    const Eigen::Isometry3d t = truth[k];
    const Eigen::Matrix3d rotation =
        t.linear() * Eigen::AngleAxisd(dr.norm(), dr.normalized()).toRotationMatrix();
    out.graph.poses[k] = make_se3_pose(t.translation() + dt, Eigen::Quaterniond(rotation));
  }
  out.graph.fixed_vertex = 0;
  return out;
}

}  // namespace backend
}  // namespace covox

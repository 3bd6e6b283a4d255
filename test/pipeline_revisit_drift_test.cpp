// The odometry's drift as revisits show it (pipeline/revisit_drift.h): the rates against the
// disagreement of composed 3-D transforms, and which constraints count.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/revisit_drift.h"
#include "covoxslam/pipeline/submap.h"
#include "covoxslam/pipeline/submap_pose_graph.h"

namespace covox {
namespace pipeline {
namespace {

Eigen::Isometry3d planar_pose(double x, double y, double z, double yaw_rad) {
  return to_isometry(backend::Pose4Dof{x, y, z, yaw_rad});
}

backend::Pose4Dof to_4dof(const Eigen::Isometry3d& pose) { return pose_4dof_from_isometry(pose); }

SubmapConstraint relative(SubmapConstraintKind kind, int64_t from, int64_t to,
                          const Eigen::Isometry3d& from_to) {
  SubmapConstraint c;
  c.kind = kind;
  c.from_submap = from;
  c.to_submap = to;
  c.measurement = to_4dof(from_to);
  c.information = Eigen::Matrix4d::Identity();
  return c;
}

// A circle of `n` submaps whose odometry has the same bias on every link: a body-frame offset
// and a yaw step, as a scale and yaw-rate bias give.
struct BiasedCircle {
  std::vector<Eigen::Isometry3d> truth;
  std::vector<Eigen::Isometry3d> link;  // link[k]: the odometry from submap k - 1 to k
  std::vector<double> path_m;           // path to each submap's start
  SubmapPoseGraph graph;
};

BiasedCircle biased_circle(int n, double radius_m) {
  BiasedCircle c;
  const Eigen::Isometry3d bias = planar_pose(0.04, -0.02, 0.01, 0.003);
  for (int k = 0; k < n; ++k) {
    const double angle = 2.0 * 3.14159265358979323846 * k / n;
    c.truth.push_back(planar_pose(radius_m * std::cos(angle), radius_m * std::sin(angle),
                                  0.2 * std::sin(3.0 * angle), angle + 1.5707963267948966));
    c.graph.add_submap(k, to_4dof(c.truth.back()), false);
    c.link.push_back(Eigen::Isometry3d::Identity());
    c.path_m.push_back(0.0);
    if (k == 0) continue;
    c.link[k] = c.truth[k - 1].inverse() * c.truth[k] * bias;
    c.path_m[k] =
        c.path_m[k - 1] + (c.truth[k].translation() - c.truth[k - 1].translation()).norm();
    c.graph.add_constraint(relative(SubmapConstraintKind::kOdometry, k - 1, k, c.link[k]));
  }
  return c;
}

TEST(PipelineRevisitDrift, RatesMatchTheComposedOdometryAgainstTheRevisits) {
  BiasedCircle c = biased_circle(60, 40.0);
  // Revisits measured without error: pairs a third and half the circle apart, and neighbours.
  const int pairs[][2] = {{2, 22}, {5, 35}, {10, 40}, {30, 59}, {7, 8}, {40, 41}};
  double sum_t = 0.0, sum_yaw = 0.0, sum_path = 0.0;
  int counted = 0;
  const double min_path_m = 20.0;
  for (const auto& pair : pairs) {
    const int a = pair[0], b = pair[1];
    const Eigen::Isometry3d true_ab = c.truth[a].inverse() * c.truth[b];
    c.graph.add_constraint(relative(SubmapConstraintKind::kRegistration, a, b, true_ab));
    const double path_m = c.path_m[b] - c.path_m[a];
    if (path_m < min_path_m) continue;
    Eigen::Isometry3d odometry_ab = Eigen::Isometry3d::Identity();
    for (int k = a + 1; k <= b; ++k) odometry_ab = odometry_ab * c.link[k];
    // Both translations in their own `from` frame (gravity-aligned: the 4-DoF convention).
    sum_t += (true_ab.translation() - odometry_ab.translation()).squaredNorm();
    const Eigen::Matrix3d turn = odometry_ab.linear().transpose() * true_ab.linear();
    const double yaw = std::atan2(turn(1, 0), turn(0, 0));
    sum_yaw += yaw * yaw;
    sum_path += path_m * path_m;
    ++counted;
  }
  ASSERT_EQ(counted, 4);
  const RevisitDrift drift = estimate_revisit_drift(c.graph, c.path_m, min_path_m);
  EXPECT_EQ(drift.revisits, 4);
  EXPECT_NEAR(drift.m_per_m, std::sqrt(sum_t / sum_path), 1e-9);
  EXPECT_NEAR(drift.rad_per_m, std::sqrt(sum_yaw / sum_path), 1e-12);
  // The yaw bias of 0.003 rad a link over links of 2 pi 40 / 60 m.
  EXPECT_NEAR(drift.rad_per_m, 0.003 / (2.0 * 40.0 * std::sin(3.14159265358979323846 / 60.0)),
              1e-6);
}

TEST(PipelineRevisitDrift, SkipsShortSpansSetAsideConstraintsAndBrokenChains) {
  BiasedCircle c = biased_circle(30, 20.0);
  // A chain with no odometry link into submap 30: a pair across it is not measured.
  c.graph.add_submap(30, to_4dof(c.truth[0]), false);
  c.path_m.push_back(c.path_m.back() + 5.0);
  c.graph.add_constraint(
      relative(SubmapConstraintKind::kRegistration, 0, 30, planar_pose(0.0, 0.0, 0.0, 0.0)));
  c.graph.add_constraint(
      relative(SubmapConstraintKind::kRegistration, 3, 4, c.truth[3].inverse() * c.truth[4]));
  RevisitDrift drift = estimate_revisit_drift(c.graph, c.path_m, 10.0);
  EXPECT_EQ(drift.revisits, 0);
  EXPECT_EQ(drift.m_per_m, 0.0);
  EXPECT_EQ(drift.rad_per_m, 0.0);

  c.graph.add_constraint(
      relative(SubmapConstraintKind::kRegistration, 2, 25, c.truth[2].inverse() * c.truth[25]));
  EXPECT_EQ(estimate_revisit_drift(c.graph, c.path_m, 10.0).revisits, 1);
  EXPECT_GT(estimate_revisit_drift(c.graph, c.path_m, 10.0).m_per_m, 0.0);
  c.graph.set_active(c.graph.constraints().size() - 1, false);
  EXPECT_EQ(estimate_revisit_drift(c.graph, c.path_m, 10.0).revisits, 0);
}

TEST(PipelineRevisitDrift, RejectsAPathListOfTheWrongSize) {
  BiasedCircle c = biased_circle(10, 10.0);
  c.path_m.pop_back();
  EXPECT_THROW(estimate_revisit_drift(c.graph, c.path_m, 10.0), Error);
  c.path_m.push_back(100.0);
  EXPECT_THROW(estimate_revisit_drift(c.graph, c.path_m, 0.0), Error);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

// The pieces between external input and the backend's 4-DoF graph: the loop closure's 6-DoF to
// 4-DoF projection (against the marginal covariance from numeric differences), the information
// checks, and the submap graph's loaded-map vertex, lever arms and gauge choice.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/external_constraints.h"
#include "covoxslam/pipeline/graph_optimizer.h"
#include "covoxslam/pipeline/slam_system.h"
#include "covoxslam/pipeline/submap.h"
#include "covoxslam/pipeline/submap_pose_graph.h"

namespace covox {
namespace pipeline {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

Eigen::Isometry3d make_pose(double x, double y, double z, double roll, double pitch, double yaw) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                   Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                      .toRotationMatrix();
  pose.translation() = Eigen::Vector3d(x, y, z);
  return pose;
}

// (t, yaw) of T_Sa_Sb as a function of the perturbation d = (dt, dtheta) of T_from_to, in the
// convention of LoopClosure: (t + dt, Exp(dtheta) R).
Eigen::Vector4d relative_4dof(const Eigen::Isometry3d& A, const Eigen::Isometry3d& T,
                              const Eigen::Isometry3d& B, const Eigen::Matrix<double, 6, 1>& d) {
  Eigen::Isometry3d perturbed = T;
  perturbed.translation() += d.head<3>();
  const Eigen::Vector3d angle_axis = d.tail<3>();
  const double angle = angle_axis.norm();
  const Eigen::Matrix3d exp = angle > 0.0
                                  ? Eigen::AngleAxisd(angle, angle_axis / angle).toRotationMatrix()
                                  : Eigen::Matrix3d::Identity();
  perturbed.linear() = exp * T.linear();
  const Eigen::Isometry3d relative = A * perturbed * B.inverse();
  const backend::Pose4Dof p = pose_4dof_from_isometry(relative);
  return Eigen::Vector4d(p.x, p.y, p.z, p.yaw);
}

TEST(PipelineSubmapPoseGraph, LoopClosureProjectionMatchesTheNumericMarginalCovariance) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int trial = 0; trial < 5; ++trial) {
    // Gravity-aligned submap frames, tilted sensors: consistent with gravity, as real closures are.
    const Eigen::Isometry3d W_Sa =
        make_pose(3 * uniform(rng), 3 * uniform(rng), uniform(rng), 0, 0, 3 * uniform(rng));
    const Eigen::Isometry3d W_Sb =
        make_pose(3 * uniform(rng), 3 * uniform(rng), uniform(rng), 0, 0, 3 * uniform(rng));
    const Eigen::Isometry3d A =
        make_pose(4 * uniform(rng), 4 * uniform(rng), uniform(rng), 0.1 * uniform(rng),
                  0.1 * uniform(rng), 3 * uniform(rng));  // T_Sa_from
    const Eigen::Isometry3d B =
        make_pose(4 * uniform(rng), 4 * uniform(rng), uniform(rng), 0.1 * uniform(rng),
                  0.1 * uniform(rng), 3 * uniform(rng));                  // T_Sb_to
    const Eigen::Isometry3d T = A.inverse() * W_Sa.inverse() * W_Sb * B;  // T_from_to
    Matrix6d M = Matrix6d::Random();
    const Matrix6d information = M * M.transpose() + 0.5 * Matrix6d::Identity();

    const RelativeConstraint4Dof projected = project_loop_closure(A, T, B, information);
    const backend::Pose4Dof expected = pose_4dof_from_isometry(W_Sa.inverse() * W_Sb);
    EXPECT_NEAR(projected.measurement.x, expected.x, 1e-9);
    EXPECT_NEAR(projected.measurement.y, expected.y, 1e-9);
    EXPECT_NEAR(projected.measurement.z, expected.z, 1e-9);
    EXPECT_NEAR(std::remainder(projected.measurement.yaw - expected.yaw, 2 * M_PI), 0.0, 1e-9);

    // Independent route: J by central differences, Sigma_4 = J Sigma_6 J^T, information = inverse.
    Eigen::Matrix<double, 4, 6> J;
    const double h = 1e-6;
    for (int k = 0; k < 6; ++k) {
      Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
      d(k) = h;
      Eigen::Vector4d difference = relative_4dof(A, T, B, d) - relative_4dof(A, T, B, -d);
      difference(3) = std::remainder(difference(3), 2 * M_PI);
      J.col(k) = difference / (2 * h);
    }
    const Eigen::Matrix4d covariance = J * information.inverse() * J.transpose();
    const Eigen::Matrix4d numeric_information = covariance.inverse();
    const double scale = numeric_information.cwiseAbs().maxCoeff();
    EXPECT_LT((projected.information - numeric_information).cwiseAbs().maxCoeff(), 1e-5 * scale)
        << "trial " << trial << "\nprojected\n"
        << projected.information << "\nnumeric\n"
        << numeric_information;
  }
}

TEST(PipelineSubmapPoseGraph, LoopClosureWithoutRollPitchInformationKeepsTheOtherEntries) {
  // Sensors at the submap origins, level: the projection is just the (x, y, z, yaw) entries.
  Matrix6d information = Matrix6d::Zero();
  information.diagonal() << 1.0, 2.0, 3.0, 0.0, 0.0, 4.0;
  const Eigen::Isometry3d T = make_pose(1.0, 2.0, 0.5, 0.0, 0.0, 0.3);
  const RelativeConstraint4Dof projected = project_loop_closure(
      Eigen::Isometry3d::Identity(), T, Eigen::Isometry3d::Identity(), information);
  Eigen::Matrix4d expected = Eigen::Matrix4d::Zero();
  expected.diagonal() << 1.0, 2.0, 3.0, 4.0;
  EXPECT_LT((projected.information - expected).cwiseAbs().maxCoeff(), 1e-12)
      << projected.information;
  EXPECT_NEAR(projected.measurement.yaw, 0.3, 1e-12);
}

TEST(PipelineSubmapPoseGraph, InformationChecksNameTheProblem) {
  EXPECT_TRUE(information_problem(Eigen::Matrix3d::Identity()).empty());
  Eigen::Matrix3d semi_definite = Eigen::Matrix3d::Zero();
  semi_definite(2, 2) = 5.0;
  EXPECT_TRUE(information_problem(semi_definite).empty());
  EXPECT_NE(information_problem(Eigen::Matrix3d::Zero()).find("zero"), std::string::npos);
  Eigen::Matrix3d asymmetric = Eigen::Matrix3d::Identity();
  asymmetric(0, 1) = 0.5;
  EXPECT_NE(information_problem(asymmetric).find("symmetric"), std::string::npos);
  Eigen::Matrix3d indefinite = Eigen::Matrix3d::Identity();
  indefinite(1, 1) = -1.0;
  EXPECT_NE(information_problem(indefinite).find("positive semi-definite"), std::string::npos);
  Eigen::Matrix3d not_finite = Eigen::Matrix3d::Identity();
  not_finite(0, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(information_problem(not_finite).find("finite"), std::string::npos);

  LoopClosure closure;
  closure.from_stamp_s = 1.0;
  closure.to_stamp_s = 2.0;
  EXPECT_TRUE(loop_closure_problem(closure).empty());
  LoopClosure scaled = closure;
  scaled.T_from_to.linear() *= 1.1;
  EXPECT_NE(loop_closure_problem(scaled).find("rigid"), std::string::npos);
  LoopClosure nan_stamp = closure;
  nan_stamp.to_stamp_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(loop_closure_problem(nan_stamp).find("stamp"), std::string::npos);
}

backend::Pose4Dof pose(double x, double y, double z, double yaw) {
  backend::Pose4Dof p;
  p.x = x;
  p.y = y;
  p.z = z;
  p.yaw = yaw;
  return p;
}

void expect_pose_near(const backend::Pose4Dof& actual, const backend::Pose4Dof& expected,
                      double tolerance) {
  EXPECT_NEAR(actual.x, expected.x, tolerance);
  EXPECT_NEAR(actual.y, expected.y, tolerance);
  EXPECT_NEAR(actual.z, expected.z, tolerance);
  EXPECT_NEAR(std::remainder(actual.yaw - expected.yaw, 2 * M_PI), 0.0, tolerance);
}

TEST(PipelineSubmapPoseGraph, ComposeAndInverseAreConsistentWithRelativePose) {
  const backend::Pose4Dof a = pose(1.0, -2.0, 0.5, 0.7), b = pose(-0.3, 4.0, 1.0, -2.9);
  expect_pose_near(compose(a, backend::inverse_pose_4dof(a)), backend::Pose4Dof(), 1e-12);
  expect_pose_near(compose(a, relative_pose_4dof(a, b)), b, 1e-12);
  const Eigen::Isometry3d product = to_isometry(a) * to_isometry(b);
  expect_pose_near(compose(a, b), pose_4dof_from_isometry(product), 1e-12);
}

TEST(PipelineSubmapPoseGraph, LoadedSubmapsShareOneFixedVertexAndConstraintsCarryOverExactly) {
  SubmapPoseGraph graph;
  const backend::Pose4Dof loaded0 = pose(0.0, 0.0, 0.0, 0.0), loaded1 = pose(5.0, 1.0, 0.2, 0.8);
  graph.add_submap(3, loaded0, true);
  graph.add_submap(7, loaded1, true);
  graph.add_submap(8, pose(9.0, 3.0, 0.0, 1.0), false);  // a rough guess
  graph.add_submap(9, pose(12.0, 5.0, 0.0, 1.2), false);
  // A registration from loaded submap 7 to the new submap 8, and odometry 8 -> 9.
  SubmapConstraint registration;
  registration.kind = SubmapConstraintKind::kRegistration;
  registration.from_submap = 7;
  registration.to_submap = 8;
  registration.measurement = pose(2.0, 1.5, -0.1, 0.3);
  registration.information = Eigen::Matrix4d::Identity() * 1e4;
  registration.information(0, 1) = registration.information(1, 0) =
      3e3;  // correlated: rotated with the offset
  graph.add_constraint(registration);
  SubmapConstraint odometry;
  odometry.kind = SubmapConstraintKind::kOdometry;
  odometry.from_submap = 8;
  odometry.to_submap = 9;
  odometry.measurement = pose(3.0, 0.0, 0.0, 0.1);
  odometry.information = Eigen::Matrix4d::Identity() * 100.0;
  graph.add_constraint(odometry);
  // A constraint may not end in the loaded map.
  SubmapConstraint backwards = registration;
  backwards.from_submap = 8;
  backwards.to_submap = 7;
  EXPECT_THROW(graph.add_constraint(backwards), Error);
  EXPECT_THROW(graph.add_submap(5, pose(0, 0, 0, 0), false), Error);  // ids must increase

  SubmapPoseGraph::BackendGraph backend_graph = graph.to_backend_graph();
  ASSERT_EQ(backend_graph.graph.poses.size(), 3u);  // both loaded submaps on one vertex
  EXPECT_EQ(backend_graph.graph.fixed_vertex, 0);
  EXPECT_EQ(backend_graph.vertex_of_node[0], backend_graph.vertex_of_node[1]);
  backend::solve_pose_graph(&backend_graph.graph, Device::kCpu);
  graph.apply_solution(backend_graph);
  // Consistent constraints: the solution satisfies both exactly; the loaded poses did not move.
  expect_pose_near(graph.nodes()[0].pose, loaded0, 1e-12);
  expect_pose_near(graph.nodes()[1].pose, loaded1, 1e-12);
  const backend::Pose4Dof expected8 = compose(loaded1, registration.measurement);
  expect_pose_near(graph.nodes()[2].pose, expected8, 1e-6);
  expect_pose_near(graph.nodes()[3].pose, compose(expected8, odometry.measurement), 1e-6);
}

TEST(PipelineSubmapPoseGraph, TwoHorizontalAbsolutePositionsReplaceTheFixedFirstSubmap) {
  SubmapPoseGraph graph;
  graph.add_submap(0, pose(0, 0, 0, 0), false);
  graph.add_submap(1, pose(4, 0, 0, 0), false);
  SubmapConstraint gnss;
  gnss.kind = SubmapConstraintKind::kAbsolutePosition;
  gnss.from_submap = 0;
  gnss.information.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity();
  graph.add_constraint(gnss);
  EXPECT_EQ(graph.to_backend_graph().graph.fixed_vertex, 0);
  SubmapConstraint height;
  height.kind = SubmapConstraintKind::kHeight;
  height.from_submap = 1;
  height.information(2, 2) = 1.0;
  graph.add_constraint(height);
  EXPECT_EQ(graph.to_backend_graph().graph.fixed_vertex, 0);  // a height does not pin x, y
  gnss.from_submap = 1;
  gnss.lever_arm_m = Eigen::Vector3d(1.0, 0.0, 0.5);
  graph.add_constraint(gnss);
  const SubmapPoseGraph::BackendGraph backend_graph = graph.to_backend_graph();
  EXPECT_EQ(backend_graph.graph.fixed_vertex, backend::kNoVertex);
  // The lever arm moved to the origin with the current yaw (0): position - (1, 0, 0.5).
  const backend::Constraint4Dof& last = backend_graph.graph.constraints.back();
  EXPECT_NEAR(last.measurement.x, -1.0, 1e-12);
  EXPECT_NEAR(last.measurement.z, -0.5, 1e-12);
  SubmapConstraint unknown = gnss;
  unknown.from_submap = 42;
  EXPECT_THROW(graph.add_constraint(unknown), Error);
}

// A loop of 12 submaps on a 10 m circle: odometry with a steady drift (0.15 m, 0.05 m and 0.6
// degrees per link), registrations of consecutive submaps and revisits across the loop's closure at
// their true values, and one revisit 2 m wrong (an aliased minimum).
struct GateLoop {
  std::vector<backend::Pose4Dof> truth;
  SubmapPoseGraph graph;
  size_t wrong_index = 0;  // in graph.constraints()
};

GateLoop gate_loop() {
  GateLoop loop;
  const int n = 12;
  for (int k = 0; k < n; ++k) {
    const double angle = 2.0 * M_PI * k / n;
    loop.truth.push_back(
        pose(10.0 * std::cos(angle), 10.0 * std::sin(angle), 0.1 * k, angle + 0.5 * M_PI));
  }
  backend::Pose4Dof chain = loop.truth[0];
  loop.graph.add_submap(0, chain, false);
  const backend::Pose4Dof drift = pose(0.15, 0.05, 0.0, 0.6 * kDegToRad);
  for (int k = 1; k < n; ++k) {
    SubmapConstraint odometry;
    odometry.kind = SubmapConstraintKind::kOdometry;
    odometry.from_submap = k - 1;
    odometry.to_submap = k;
    odometry.measurement = compose(relative_pose_4dof(loop.truth[k - 1], loop.truth[k]), drift);
    odometry.information = Eigen::Vector4d(100.0, 100.0, 100.0, 1e4).asDiagonal();
    chain = compose(chain, odometry.measurement);
    loop.graph.add_submap(k, chain, false);  // the odometry's guess
    loop.graph.add_constraint(odometry);
  }
  auto registration = [&](int from, int to, const backend::Pose4Dof& error) {
    SubmapConstraint c;
    c.kind = SubmapConstraintKind::kRegistration;
    c.from_submap = from;
    c.to_submap = to;
    c.measurement = compose(relative_pose_4dof(loop.truth[from], loop.truth[to]), error);
    c.information = Eigen::Vector4d(25.0, 25.0, 25.0, 3283.0).asDiagonal();  // 0.2 m, 1 degree
    loop.graph.add_constraint(c);
  };
  for (int k = 1; k < n; ++k) registration(k - 1, k, pose(0, 0, 0, 0));
  registration(0, 11, pose(0, 0, 0, 0));
  registration(1, 11, pose(0, 0, 0, 0));
  registration(0, 10, pose(0, 0, 0, 0));
  registration(1, 10, pose(0, 0, 0, 0));
  loop.wrong_index = loop.graph.constraints().size();
  registration(2, 10, pose(2.0, 0.0, 0.0, 0.0));
  return loop;
}

double max_horizontal_error(const SubmapPoseGraph& graph,
                            const std::vector<backend::Pose4Dof>& truth) {
  double worst = 0.0;
  for (size_t k = 0; k < truth.size(); ++k) {
    const backend::Pose4Dof& p = graph.nodes()[k].pose;
    worst = std::max(worst, std::hypot(p.x - truth[k].x, p.y - truth[k].y));
  }
  return worst;
}

void solve(SubmapPoseGraph* graph) {
  SubmapPoseGraph::BackendGraph backend_graph = graph->to_backend_graph();
  backend::solve_pose_graph(&backend_graph.graph, Device::kCpu);
  graph->apply_solution(backend_graph);
}

TEST(PipelineSubmapPoseGraph, ConsistencyGateMeasuresResidualsInTheFromFrameAndSkipsOtherKinds) {
  GateLoop loop = gate_loop();
  // At the true poses the right constraints have no residual and the wrong one 2 m, whatever the
  // submaps' headings (the measurement is in the frame of `from`; submap 2 faces 150 degrees).
  SubmapPoseGraph at_truth;
  for (size_t k = 0; k < loop.truth.size(); ++k)
    at_truth.add_submap(static_cast<int64_t>(k), loop.truth[k], false);
  for (const SubmapConstraint& c : loop.graph.constraints()) at_truth.add_constraint(c);
  EXPECT_EQ(set_aside_inconsistent_registrations(&at_truth, 1.99), 1);
  for (size_t k = 0; k < at_truth.constraints().size(); ++k) {
    EXPECT_EQ(at_truth.constraints()[k].active, k != loop.wrong_index) << k;
  }
  // Already set aside: not counted again. Odometry (0.16 m off per link here) is never touched.
  EXPECT_EQ(set_aside_inconsistent_registrations(&at_truth, 1e-3), 0);
  for (const SubmapConstraint& c : at_truth.constraints()) {
    if (c.kind == SubmapConstraintKind::kOdometry) {
      EXPECT_TRUE(c.active);
    }
  }
  // An inactive constraint is left out of the backend graph.
  const size_t active = at_truth.to_backend_graph().graph.constraints.size();
  at_truth.set_active(loop.wrong_index, true);
  EXPECT_EQ(at_truth.to_backend_graph().graph.constraints.size(), active + 1);
  EXPECT_THROW(at_truth.set_active(at_truth.constraints().size(), false), Error);
}

TEST(PipelineSubmapPoseGraph, ConsistencyGateLeavesConfirmedLoopClosuresToTheirOwnTest) {
  // The same loop with the wrong registration marked as a place-recognition closure: its 2 m are
  // not the gate's to judge (the closures' confirmation is), so nothing is set aside.
  GateLoop loop = gate_loop();
  SubmapPoseGraph at_truth;
  for (size_t k = 0; k < loop.truth.size(); ++k)
    at_truth.add_submap(static_cast<int64_t>(k), loop.truth[k], false);
  for (size_t k = 0; k < loop.graph.constraints().size(); ++k) {
    SubmapConstraint c = loop.graph.constraints()[k];
    c.from_place_recognition = k == loop.wrong_index;
    at_truth.add_constraint(c);
  }
  EXPECT_EQ(set_aside_inconsistent_registrations(&at_truth, 1.99), 0);
  EXPECT_TRUE(at_truth.constraints()[loop.wrong_index].active);
}

TEST(PipelineSubmapPoseGraph, ConsistencyGateWorstFirstSetsAsideOnlyTheLargestResiduals) {
  // At the true poses: the wrong revisit 2 m off, two more registrations 0.8 m and 0.3 m off.
  GateLoop loop = gate_loop();
  SubmapPoseGraph at_truth;
  for (size_t k = 0; k < loop.truth.size(); ++k)
    at_truth.add_submap(static_cast<int64_t>(k), loop.truth[k], false);
  for (const SubmapConstraint& c : loop.graph.constraints()) at_truth.add_constraint(c);
  const size_t off_08 = at_truth.constraints().size(), off_03 = off_08 + 1;
  for (const double offset_m : {0.8, 0.3}) {
    SubmapConstraint c = at_truth.constraints()[loop.wrong_index];
    c.measurement = compose(relative_pose_4dof(loop.truth[c.from_submap], loop.truth[c.to_submap]),
                            pose(0.0, offset_m, 0.0, 0.0));
    at_truth.add_constraint(c);
  }
  auto set_aside_list = [&]() {
    std::vector<size_t> aside;
    for (size_t k = 0; k < at_truth.constraints().size(); ++k) {
      if (!at_truth.constraints()[k].active) aside.push_back(k);
    }
    return aside;
  };
  SubmapPoseGraph all_at_once = at_truth;
  // Fraction 0: everything above the threshold at once.
  EXPECT_EQ(set_aside_inconsistent_registrations(&all_at_once, 0.2, 0.0), 3);
  // Fraction 0.5 of the worst (2 m): only residuals above 1 m; then above 0.4 m (0.5 x 0.8); then
  // the threshold itself.
  EXPECT_EQ(set_aside_inconsistent_registrations(&at_truth, 0.2, 0.5), 1);
  EXPECT_EQ(set_aside_list(), std::vector<size_t>({loop.wrong_index}));
  EXPECT_EQ(set_aside_inconsistent_registrations(&at_truth, 0.2, 0.5), 1);
  EXPECT_EQ(set_aside_list(), std::vector<size_t>({loop.wrong_index, off_08}));
  EXPECT_EQ(set_aside_inconsistent_registrations(&at_truth, 0.2, 0.5), 1);
  EXPECT_EQ(set_aside_list(), std::vector<size_t>({loop.wrong_index, off_08, off_03}));
  EXPECT_EQ(set_aside_inconsistent_registrations(&at_truth, 0.2, 0.5), 0);
}

TEST(PipelineSubmapPoseGraph, ConsistencyGateSetsAsideTheWrongRevisitAndTheLoopCloses) {
  GateLoop without = gate_loop();
  solve(&without.graph);
  // The reference: the same graph built without the wrong revisit.
  GateLoop oracle = gate_loop();
  oracle.graph.set_active(oracle.wrong_index, false);
  solve(&oracle.graph);

  GateLoop with = gate_loop();
  int rounds = 0, set_aside = 0;
  for (; rounds < 10; ++rounds) {
    solve(&with.graph);
    const int now = set_aside_inconsistent_registrations(&with.graph, 0.5);
    set_aside += now;
    if (now == 0) break;
  }
  const double error_without = max_horizontal_error(without.graph, without.truth);
  const double error_oracle = max_horizontal_error(oracle.graph, oracle.truth);
  const double error_with = max_horizontal_error(with.graph, with.truth);
  std::printf(
      "[ gate     ] max error: all constraints %.3f m, gate %.3f m (%d set aside, %d solves), "
      "without the wrong revisit %.3f m\n",
      error_without, error_with, set_aside, rounds + 1, error_oracle);
  EXPECT_EQ(set_aside, 1);
  for (size_t k = 0; k < with.graph.constraints().size(); ++k) {
    EXPECT_EQ(with.graph.constraints()[k].active, k != with.wrong_index) << k;
  }
  // The gate ends at the graph without the wrong revisit, which the wrong revisit pulls further
  // off.
  for (size_t k = 0; k < with.truth.size(); ++k) {
    expect_pose_near(with.graph.nodes()[k].pose, oracle.graph.nodes()[k].pose, 1e-4);
  }
  EXPECT_GT(error_without, error_oracle + 0.03);
}

// The robust loss's weights: at the true poses of the gate's loop, the right registrations have no
// residual (weight 1) and the wrong one (2 m off at 0.2 m sigma: r^2 = 100) gets 1 / (1 + 100 / 9)
// at a scale of 3 sigmas.
TEST(PipelineSubmapPoseGraph, CauchyWeightsFollowTheWhitenedResidual) {
  GateLoop loop = gate_loop();
  SubmapPoseGraph at_truth;
  for (size_t k = 0; k < loop.truth.size(); ++k)
    at_truth.add_submap(static_cast<int64_t>(k), loop.truth[k], false);
  for (const SubmapConstraint& c : loop.graph.constraints()) at_truth.add_constraint(c);
  reweight_registrations_cauchy(&at_truth, 3.0);
  for (size_t k = 0; k < at_truth.constraints().size(); ++k) {
    const SubmapConstraint& c = at_truth.constraints()[k];
    const double expected = k == loop.wrong_index ? 1.0 / (1.0 + 25.0 * 4.0 / 9.0) : 1.0;
    EXPECT_NEAR(c.weight, expected, 1e-9) << k;
  }
}

// Reweighted solves (the robust loss) keep the wrong revisit from bending the loop: the result
// lies nearer the graph without it than the plain solve does, and its weight ends small.
TEST(PipelineSubmapPoseGraph, CauchyLossKeepsTheWrongRevisitFromBendingTheLoop) {
  GateLoop plain = gate_loop();
  solve(&plain.graph);
  GateLoop oracle = gate_loop();
  oracle.graph.set_active(oracle.wrong_index, false);
  solve(&oracle.graph);
  GateLoop robust = gate_loop();
  for (int round = 0; round < 20; ++round) {
    solve(&robust.graph);
    if (reweight_registrations_cauchy(&robust.graph, 3.0) < 1e-3) break;
  }
  solve(&robust.graph);
  const double error_plain = max_horizontal_error(plain.graph, plain.truth);
  const double error_oracle = max_horizontal_error(oracle.graph, oracle.truth);
  const double error_robust = max_horizontal_error(robust.graph, robust.truth);
  std::printf(
      "[ cauchy   ] max error: plain %.3f m, robust %.3f m, without the wrong revisit %.3f m\n",
      error_plain, error_robust, error_oracle);
  EXPECT_LT(robust.graph.constraints()[robust.wrong_index].weight, 0.1);
  EXPECT_LT(error_robust - error_oracle, 0.25 * (error_plain - error_oracle));
}

// A pose graph of its own as the optimiser's graph (what the SLAM system gives it).
class PlainGraph : public OptimizedGraph {
 public:
  explicit PlainGraph(SubmapPoseGraph* graph) : graph_(graph) {}
  void edit(const std::function<void(SubmapPoseGraph&)>& change) override { change(*graph_); }
  SolverInput solver_input() override {
    SolverInput input;
    input.graph = graph_->to_backend_graph();
    return input;
  }
  void apply(const SubmapPoseGraph::BackendGraph& solved, const backend::PoseGraphSolverSummary&,
             double) override {
    graph_->apply_solution(solved);
  }
  std::vector<double> path_at_node_m() override { return std::vector<double>(graph_->size(), 0.0); }

 private:
  SubmapPoseGraph* graph_;
};

// The gate alone: plain least squares and fixed odometry sigmas, so that every solve is a round.
SlamConfig gated_config(int max_solves_per_new_submap) {
  SlamConfig config;
  config.registration.gate.max_residual_vox = 0.5 / config.map.voxel_size_m;  // 0.5 m
  config.registration_loss_scale_sigmas = 0.0;
  config.estimate_odometry_noise = false;
  config.max_solves_per_new_submap = max_solves_per_new_submap;
  return config;
}

// The optimiser's gate ends where the graph without the wrong revisit is (solved by hand), and
// its report counts the solves of its rounds: solve, set one aside, solve, nothing left.
TEST(PipelineGraphOptimizer, GateEndsAtTheGraphWithoutTheWrongRevisit) {
  GateLoop oracle = gate_loop();
  oracle.graph.set_active(oracle.wrong_index, false);
  solve(&oracle.graph);
  GateLoop loop = gate_loop();
  PlainGraph graph(&loop.graph);
  const OptimizationReport report = GraphOptimizer(gated_config(100)).optimize(graph, 1);
  EXPECT_TRUE(report.gate_finished);
  EXPECT_FALSE(report.budget_exhausted);
  EXPECT_EQ(report.set_aside, 1);
  EXPECT_EQ(report.solves, 2);
  EXPECT_EQ(report.failed_solves, 0);
  EXPECT_FALSE(loop.graph.constraints()[loop.wrong_index].active);
  for (size_t k = 0; k < loop.truth.size(); ++k)
    expect_pose_near(loop.graph.nodes()[k].pose, oracle.graph.nodes()[k].pose, 1e-4);
}

// A budget of one solve stops the gate after its first round: the graph keeps the plain solve
// of every constraint (solved by hand), the report says the budget ran out, and the budget
// scales with the submaps that entered the graph since the previous optimisation.
TEST(PipelineGraphOptimizer, BudgetStopsTheRoundsWithTheLatestSolutionKept) {
  GateLoop plain = gate_loop();
  solve(&plain.graph);
  GateLoop loop = gate_loop();
  PlainGraph graph(&loop.graph);
  const OptimizationReport report = GraphOptimizer(gated_config(1)).optimize(graph, 1);
  EXPECT_TRUE(report.budget_exhausted);
  EXPECT_FALSE(report.gate_finished);
  EXPECT_EQ(report.budget, 1);
  EXPECT_EQ(report.solves, 1);
  for (size_t k = 0; k < loop.truth.size(); ++k)
    expect_pose_near(loop.graph.nodes()[k].pose, plain.graph.nodes()[k].pose, 1e-9);

  GateLoop again = gate_loop();
  PlainGraph graph_again(&again.graph);
  const OptimizationReport two_new = GraphOptimizer(gated_config(1)).optimize(graph_again, 2);
  EXPECT_EQ(two_new.budget, 2);
  EXPECT_TRUE(two_new.gate_finished);
  EXPECT_EQ(two_new.solves, 2);
}

TEST(PipelineGraphOptimizer, RejectsABudgetBelowOneSolve) {
  SlamConfig config;
  config.max_solves_per_new_submap = 0;
  EXPECT_THROW(validate(config), Error);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

// Dense registration terms inside the 4-DoF pose graph: the per-pair sums reduced on the device
// against a host sum over the single-pair residuals, the solution against the truth and against
// Ceres on the same problem, bad input, and CPU/GPU parity.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <vector>

#include "covoxslam/backend/ceres_registration_oracle.h"
#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/internal/registration_ops.h"
#include "covoxslam/backend/registration_terms.h"
#include "covoxslam/core/error.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "support/analytic_scene.h"
#include "support/per_device_cache.h"
#include "support/registration_room.h"
#include "support/solver_test_options.h"
#include "support/test_devices.h"

namespace covox {
namespace backend {
namespace {

using testing_support::AnalyticScene;
using testing_support::DeviceTest;
using testing_support::kDegToRad;
using testing_support::relative_difference;

// Four submaps of a closed room (every face constrains x, y, z and yaw), registration terms
// between every ordered pair, odometry between consecutive submaps, vertex 0 fixed.
//
// A point whose trilinear stencil leaves j's observed field drops out of the cost, so the
// objective jumps by that point's cost wherever one crosses the edge of the field (or a hole a
// sparse scan left in it): two correct solvers then stop in different local minima that differ by
// a point or two (seen here: 8150 vs 8149 points used, 0.16 % apart). The terms therefore use only
// points that stay inside j's field over a neighbourhood of the truth far larger than the
// solvers' paths (+-10 cm, +-1.5 degrees about the truth and the initial guess), which makes the
// objective continuous where the comparison with Ceres happens.
struct RoomGraph {
  std::vector<std::unique_ptr<map::TsdfMap>> maps;
  std::vector<std::unique_ptr<RegistrationPoints>> points;  // per term (filtered as above)
  std::vector<RegistrationTerm> terms;
  std::vector<Pose4Dof> truth;
  PoseGraph4Dof graph;  // at the perturbed initial guess
};

// The initial guess: the truth moved by a few centimetres and about a degree (vertex 0 exact).
std::vector<Pose4Dof> perturbed_guess(const std::vector<Pose4Dof>& truth) {
  const Pose4Dof perturbation[4] = {{0.0, 0.0, 0.0, 0.0},
                                    {0.06, -0.04, 0.03, 1.5},
                                    {-0.05, 0.06, -0.02, -1.2},
                                    {0.04, 0.05, 0.03, 1.0}};
  std::vector<Pose4Dof> out;
  for (size_t k = 0; k < truth.size(); ++k) {
    out.push_back(Pose4Dof{truth[k].x + perturbation[k].x, truth[k].y + perturbation[k].y,
                           truth[k].z + perturbation[k].z,
                           truth[k].yaw + perturbation[k].yaw * kDegToRad});
  }
  return out;
}

// The points of `all` that are valid against map_j at every pose pair (pose_i, pose_j) from the
// given lists with pose_i also moved by +-10 cm along each axis and +-1.5 degrees of yaw.
RegistrationPoints points_inside_neighbourhood(const RegistrationPoints& all,
                                               const map::TsdfMap& map_j,
                                               const std::vector<Pose4Dof>& poses_i,
                                               const std::vector<Pose4Dof>& poses_j,
                                               const RegistrationResidualConfig& config,
                                               const Stream& stream) {
  std::vector<uint8_t> keep(all.points.size(), 1);
  for (const Pose4Dof& pose_i : poses_i) {
    std::vector<Pose4Dof> moved = {pose_i};
    for (int axis = 0; axis < 4; ++axis) {
      for (const double sign : {-1.0, 1.0}) {
        Pose4Dof p = pose_i;
        double* fields[4] = {&p.x, &p.y, &p.z, &p.yaw};
        *fields[axis] += sign * (axis == 3 ? 1.5 * kDegToRad : 0.1);
        moved.push_back(p);
      }
    }
    for (const Pose4Dof& pose_j : poses_j) {
      for (const Pose4Dof& p : moved) {
        const auto residuals = evaluate_registration_residuals(all, map_j, p, pose_j, config);
        for (size_t k = 0; k < residuals.size(); ++k) keep[k] &= residuals[k].valid;
      }
    }
  }
  const std::vector<RegistrationPoint> host = all.points.to_host(stream);
  std::vector<RegistrationPoint> kept;
  for (size_t k = 0; k < host.size(); ++k) {
    if (keep[k]) kept.push_back(host[k]);
  }
  RegistrationPoints out(all.points.device());
  out.points.copy_from_host(kept, stream);
  out.surface_voxels = all.surface_voxels;
  return out;
}

RoomGraph build_room_graph(Device device) {
  const AnalyticScene room = testing_support::registration_room();
  RoomGraph g;
  g.truth = {Pose4Dof{0.0, 0.0, 0.0, 0.0}, Pose4Dof{0.45, -0.3, 0.05, 8.0 * kDegToRad},
             Pose4Dof{0.95, 0.15, -0.04, 15.0 * kDegToRad},
             Pose4Dof{0.4, 0.55, 0.08, -6.0 * kDegToRad}};
  const Stream stream(device);
  RegistrationPointsConfig points_config;
  points_config.sampling_ratio = 0.05f;
  for (const Pose4Dof& pose : g.truth) {
    g.maps.push_back(testing_support::scan_room_submap(device, room, pose, 0.1f));
    g.points.push_back(std::make_unique<RegistrationPoints>(
        extract_registration_points(*g.maps.back(), points_config, stream)));
  }
  const int n = static_cast<int>(g.truth.size());
  const std::vector<Pose4Dof> initial = perturbed_guess(g.truth);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      if (i == j) continue;
      RegistrationTerm term;
      term.vertex_i = i;
      term.vertex_j = j;
      term.map_j = g.maps[j].get();
      term.residual.loss = (i + j) % 2 ? RobustLoss::kHuber : RobustLoss::kNone;
      term.residual.loss_scale = 0.05;
      term.residual_sigma = (i + j) % 2 ? 1.0 : 0.5;
      g.points.push_back(std::make_unique<RegistrationPoints>(
          points_inside_neighbourhood(*g.points[i], *g.maps[j], {g.truth[i], initial[i]},
                                      {g.truth[j], initial[j]}, term.residual, stream)));
      term.points_i = g.points.back().get();
      g.terms.push_back(term);
    }
  }
  // Odometry: the true relative pose plus a fixed error (a few cm, a fraction of a degree), so
  // the optimum is not the truth exactly and the registration terms have to pull it back.
  const double odometry_error[3][4] = {
      {0.03, -0.02, 0.01, 0.4}, {-0.02, 0.03, -0.01, -0.5}, {0.02, 0.02, 0.0, 0.3}};
  for (int k = 0; k + 1 < n; ++k) {
    const Pose4Dof& a = g.truth[k];
    const Pose4Dof& b = g.truth[k + 1];
    const double c = std::cos(a.yaw), s = std::sin(a.yaw);
    const Pose4Dof relative{c * (b.x - a.x) + s * (b.y - a.y) + odometry_error[k][0],
                            -s * (b.x - a.x) + c * (b.y - a.y) + odometry_error[k][1],
                            b.z - a.z + odometry_error[k][2],
                            b.yaw - a.yaw + odometry_error[k][3] * kDegToRad};
    const Eigen::Vector4d sigma(0.1, 0.1, 0.1, 2.0 * kDegToRad);
    g.graph.constraints.push_back(make_relative_constraint_4dof(
        k, k + 1, relative, sigma.cwiseInverse().cwiseAbs2().asDiagonal()));
  }
  g.graph.poses = initial;
  g.graph.fixed_vertex = 0;
  return g;
}

// Built once per device: integration dominates the test time.
const RoomGraph& room_graph(Device device) {
  return testing_support::once_per_device<RoomGraph>(device,
                                                     [](Device d) { return build_room_graph(d); });
}

PoseGraphSolverOptions tight_options() { return testing_support::tight_solver_options(1e-12, 200); }

class RegistrationGraphTest : public DeviceTest {};

// The device reduction (per point, per chunk, per pair, then into the block-sparse normal
// equations) against a plain host sum of the single-pair residuals of registration.h.
TEST_P(RegistrationGraphTest, AssembledBlocksMatchHostSums) {
  const RoomGraph& g = room_graph(device());
  const PoseGraphEvaluation with_terms = evaluate_pose_graph(g.graph, g.terms, device());
  const PoseGraphEvaluation constraints_only = evaluate_pose_graph(g.graph, device());
  const int n = static_cast<int>(g.graph.poses.size());
  std::vector<Eigen::Vector4d> gradient(n, Eigen::Vector4d::Zero());
  std::vector<Eigen::Matrix4d> diagonal(n, Eigen::Matrix4d::Zero());
  double cost = pose_graph_cost(g.graph);
  int64_t used = 0;
  for (const RegistrationTerm& t : g.terms) {
    // Plain residuals, then the term's sigma and robust loss (IRLS weight rho' of the scaled one).
    RegistrationResidualConfig plain = t.residual;
    plain.loss = RobustLoss::kNone;
    const RobustLossParams robust{t.residual.loss, t.residual.loss_scale};
    const auto residuals = evaluate_registration_residuals(
        *t.points_i, *t.map_j, g.graph.poses[t.vertex_i], g.graph.poses[t.vertex_j], plain);
    for (const RegistrationResidual& r : residuals) {
      if (!r.valid) continue;
      ++used;
      const double f = r.residual / t.residual_sigma;
      const Eigen::Vector4d ji = Eigen::Map<const Eigen::Vector4d>(r.jacobian_i) / t.residual_sigma;
      const Eigen::Vector4d jj = Eigen::Map<const Eigen::Vector4d>(r.jacobian_j) / t.residual_sigma;
      double rho = 0.0, weight = 0.0;
      robust.evaluate(f * f, &rho, &weight);
      gradient[t.vertex_i] += weight * ji * f;
      gradient[t.vertex_j] += weight * jj * f;
      diagonal[t.vertex_i] += weight * ji * ji.transpose();
      diagonal[t.vertex_j] += weight * jj * jj.transpose();
      cost += 0.5 * rho;
    }
  }
  ASSERT_GT(used, 4000) << "too few registration points overlap: the check would be weak";
  EXPECT_LT(relative_difference(with_terms.cost, cost), 1e-10);
  double gradient_scale = 0.0, hessian_scale = 0.0;
  for (int v = 1; v < n; ++v) {
    gradient_scale = std::max(gradient_scale, gradient[v].cwiseAbs().maxCoeff());
    hessian_scale = std::max(hessian_scale, diagonal[v].cwiseAbs().maxCoeff());
  }
  ASSERT_GT(gradient_scale, 0.0);
  for (int v = 1; v < n; ++v) {  // vertex 0 is fixed: identity block, zero gradient
    for (int r = 0; r < 4; ++r) {
      const double expected_g = gradient[v](r) + constraints_only.gradient[v * 4 + r];
      EXPECT_NEAR(with_terms.gradient[v * 4 + r], expected_g, 1e-10 * gradient_scale)
          << "vertex " << v;
      for (int c = 0; c < 4; ++c) {
        const double expected_h =
            diagonal[v](r, c) + constraints_only.hessian_diagonal_blocks[v * 16 + r * 4 + c];
        EXPECT_NEAR(with_terms.hessian_diagonal_blocks[v * 16 + r * 4 + c], expected_h,
                    1e-10 * hessian_scale)
            << "vertex " << v << " entry " << r << "," << c;
      }
    }
  }
  EXPECT_NEAR(registration_terms_cost(g.graph, g.terms) + pose_graph_cost(g.graph), with_terms.cost,
              1e-10 * with_terms.cost);
}

// The acceptance test for the graph: the final cost equals Ceres' on the same problem
// (voxgraph's structure: one cost function per pair) within 1e-6 relative, the solutions agree,
// and the registration terms pull the odometry-only solution back to the truth.
TEST_P(RegistrationGraphTest, SolutionMatchesCeresAndTruth) {
  const RoomGraph& g = room_graph(device());
  PoseGraph4Dof ours = g.graph;
  const PoseGraphSolverSummary summary =
      solve_pose_graph(&ours, g.terms, device(), tight_options());
  std::printf("[ registration graph ] %s: %s\n", to_string(device()), summary.report().c_str());
  EXPECT_TRUE(summary.converged()) << summary.report();
  EXPECT_LT(summary.final_cost, 0.5 * summary.initial_cost);
  EXPECT_GT(summary.registration_points_used, 4000);
  EXPECT_EQ(summary.registration_points_used,
            summary.registration_points);  // all inside, by construction
  for (size_t k = 1; k < ours.poses.size(); ++k) {
    const Pose4Dof& p = ours.poses[k];
    const Pose4Dof& t = g.truth[k];
    const double error_m =
        std::sqrt(std::pow(p.x - t.x, 2) + std::pow(p.y - t.y, 2) + std::pow(p.z - t.z, 2));
    EXPECT_LT(error_m, 0.02) << "submap " << k;
    EXPECT_LT(std::abs(p.yaw - t.yaw) / kDegToRad, 0.2) << "submap " << k;
  }
#if COVOX_HAVE_CERES
  PoseGraph4Dof reference = g.graph;
  ceres_oracle::OracleOptions options;
  options.max_iterations = 200;
  const auto oracle = ceres_oracle::solve(&reference, g.terms, options);
  std::printf("[ registration graph ] ceres: %s (%.3f s)\n", oracle.brief_report.c_str(),
              oracle.solve_time_s);
  ASSERT_TRUE(oracle.usable);
  std::printf(
      "[ registration graph ] final cost: ours %.12g, Ceres %.12g (relative difference %.2e)\n",
      summary.final_cost, oracle.final_cost,
      relative_difference(summary.final_cost, oracle.final_cost));
  EXPECT_LT(relative_difference(summary.initial_cost, oracle.initial_cost), 1e-10);
  EXPECT_LT(relative_difference(summary.final_cost, oracle.final_cost), 1e-6)
      << "ours " << summary.final_cost << ", Ceres " << oracle.final_cost;
  for (size_t k = 1; k < ours.poses.size(); ++k) {
    EXPECT_NEAR(ours.poses[k].x, reference.poses[k].x, 1e-4) << "submap " << k;
    EXPECT_NEAR(ours.poses[k].y, reference.poses[k].y, 1e-4) << "submap " << k;
    EXPECT_NEAR(ours.poses[k].z, reference.poses[k].z, 1e-4) << "submap " << k;
    EXPECT_NEAR(ours.poses[k].yaw, reference.poses[k].yaw, 1e-5) << "submap " << k;
  }
#else
  std::printf("[ registration graph ] built without Ceres: the oracle comparison did not run\n");
#endif
}

TEST_P(RegistrationGraphTest, BadTermsAreRejectedByName) {
  const RoomGraph& g = room_graph(device());
  PoseGraph4Dof graph = g.graph;
  std::vector<RegistrationTerm> terms = {g.terms.front()};
  terms[0].vertex_j = 7;
  EXPECT_THROW(solve_pose_graph(&graph, terms, device()), Error);
  terms[0].vertex_j = terms[0].vertex_i;
  EXPECT_THROW(solve_pose_graph(&graph, terms, device()), Error);
  terms = {g.terms.front()};
  terms[0].residual_sigma = 0.0;
  EXPECT_THROW(solve_pose_graph(&graph, terms, device()), Error);
  terms = {g.terms.front()};
  terms[0].map_j = nullptr;
  EXPECT_THROW(solve_pose_graph(&graph, terms, device()), Error);
  terms = {g.terms.front()};
  terms[0].residual.loss = RobustLoss::kCauchy;
  terms[0].residual.loss_scale = -1.0;
  try {
    solve_pose_graph(&graph, terms, device());
    ADD_FAILURE() << "a negative loss scale was accepted";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("registration term 0"), std::string::npos)
        << error.what();
  }
  // Terms only (no ordinary constraints) still solve.
  PoseGraph4Dof terms_only = g.graph;
  terms_only.constraints.clear();
  const PoseGraphSolverSummary summary = solve_pose_graph(&terms_only, g.terms, device());
  EXPECT_LT(summary.final_cost, summary.initial_cost);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(RegistrationGraphTest);

// The same graph on both backends: costs, gradients and solutions agree (needs a GPU).
TEST(RegistrationGraphParityTest, CpuAndCudaAgree) {
  COVOX_SKIP_WITHOUT_GPU();
  const RoomGraph& cpu = room_graph(Device::kCpu);
  const RoomGraph& gpu = room_graph(Device::kCuda);
  const PoseGraphEvaluation e_cpu = evaluate_pose_graph(cpu.graph, cpu.terms, Device::kCpu);
  const PoseGraphEvaluation e_gpu = evaluate_pose_graph(gpu.graph, gpu.terms, Device::kCuda);
  // The maps agree to TSDF parity (1e-4 m), not bit for bit.
  EXPECT_LT(relative_difference(e_gpu.cost, e_cpu.cost), 1e-3);
  double scale = 0.0;
  for (double v : e_cpu.gradient) scale = std::max(scale, std::abs(v));
  for (size_t k = 0; k < e_cpu.gradient.size(); ++k)
    EXPECT_NEAR(e_gpu.gradient[k], e_cpu.gradient[k], 1e-2 * scale);
  PoseGraph4Dof a = cpu.graph, b = gpu.graph;
  solve_pose_graph(&a, cpu.terms, Device::kCpu, tight_options());
  solve_pose_graph(&b, gpu.terms, Device::kCuda, tight_options());
  for (size_t k = 0; k < a.poses.size(); ++k) {
    EXPECT_NEAR(a.poses[k].x, b.poses[k].x, 2e-3);
    EXPECT_NEAR(a.poses[k].y, b.poses[k].y, 2e-3);
    EXPECT_NEAR(a.poses[k].z, b.poses[k].z, 2e-3);
    EXPECT_NEAR(a.poses[k].yaw, b.poses[k].yaw, 2e-4);
  }
}

}  // namespace
}  // namespace backend
}  // namespace covox

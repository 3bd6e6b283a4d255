#pragma once
// Ceres as the oracle for 4-DoF pose graphs with dense registration terms (registration_terms.h),
// for tests and benchmarks only (empty unless COVOX_HAVE_CERES). As voxgraph does it: one
// ceres::CostFunction per submap pair, one residual per registration point, evaluated on the host
// by registration_residual() against a host copy of submap j's field (a point outside it gives 0
// and a zero row, as the solver drops it). Ceres applies a loss to a whole residual block (here a
// pair), so the per-point loss is folded into the residual: s = sign(r) sqrt(rho(r^2)) has
// 0.5 s^2 = 0.5 rho(r^2), the solver's cost, and ds/dr = rho'(r^2) r / s. Only the Gauss-Newton
// Hessian differs from the solver's IRLS one, so both reach the same minimum by other paths.
#if COVOX_HAVE_CERES
#include <ceres/ceres.h>

#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <vector>

#include "covoxslam/backend/ceres_pose_graph_oracle.h"
#include "covoxslam/backend/internal/registration_ops.h"
#include "covoxslam/backend/registration_terms.h"
#include "covoxslam/backend/internal/registration_terms_ops.h"

namespace covox {
namespace backend {
namespace ceres_oracle {

class RegistrationPairCost : public ceres::CostFunction {
 public:
  RegistrationPairCost(std::vector<RegistrationPoint> points,
                       const RegistrationDistanceLookup& lookup,
                       const RegistrationResidualConfig& config, double residual_sigma)
      : points_(std::move(points)),
        lookup_(lookup),
        robust_{config.loss, config.loss_scale},
        tsdf_target_(registration_uses_tsdf_target(config)),
        inverse_sigma_(1.0 / residual_sigma) {
    set_num_residuals(static_cast<int>(points_.size()));
    mutable_parameter_block_sizes()->push_back(4);
    mutable_parameter_block_sizes()->push_back(4);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Pose4Dof pi{parameters[0][0], parameters[0][1], parameters[0][2], parameters[0][3]};
    const Pose4Dof pj{parameters[1][0], parameters[1][1], parameters[1][2], parameters[1][3]};
    const RegistrationPairGeometry geometry = registration_pair_geometry(pi, pj);
    for (size_t k = 0; k < points_.size(); ++k) {
      const RegistrationResidual r = registration_scaled_residual(
          points_[k], lookup_, geometry, robust_, tsdf_target_, inverse_sigma_);
      double s = 0.0, ds_dr = 0.0;
      if (r.valid) {
        const double rho = 2.0 * r.cost;
        s = std::copysign(std::sqrt(rho), r.residual);
        // ds/dr -> rho'(0) = 1 as r -> 0 for every loss here.
        ds_dr = std::abs(s) > 1e-150 ? r.robust_weight * r.residual / s : 1.0;
      }
      residuals[k] = s;
      if (jacobians == nullptr) continue;
      for (int a = 0; a < 4; ++a) {
        if (jacobians[0] != nullptr)
          jacobians[0][k * 4 + a] = r.valid ? ds_dr * r.jacobian_i[a] : 0.0;
        if (jacobians[1] != nullptr)
          jacobians[1][k * 4 + a] = r.valid ? ds_dr * r.jacobian_j[a] : 0.0;
      }
    }
    return true;
  }

 private:
  std::vector<RegistrationPoint> points_;
  RegistrationDistanceLookup lookup_;
  RobustLossParams robust_;
  bool tsdf_target_;
  double inverse_sigma_;
};

// Host copies of the terms' fields: CPU maps are used as they are, device maps are copied once.
class HostRegistrationFields {
 public:
  const map::TsdfMap& host_map(const map::TsdfMap* map) {
    if (map->device() == Device::kCpu) return *map;
    auto found = copies_.find(map);
    if (found != copies_.end()) return *found->second;
    auto copy = std::make_unique<map::TsdfMap>(Device::kCpu, map->config());
    copy->load_blocks(map->snapshot(), Stream(Device::kCpu));
    return *copies_.emplace(map, std::move(copy)).first->second;
  }

 private:
  std::map<const map::TsdfMap*, std::unique_ptr<map::TsdfMap>> copies_;
};

// Solves `graph` (constraints and registration terms) in place with Ceres. `fields` keeps the
// host copies of device maps across calls (benchmarks repeat solves); may be null.
inline OracleResult solve(PoseGraph4Dof* graph, const std::vector<RegistrationTerm>& terms,
                          const OracleOptions& o = OracleOptions(),
                          HostRegistrationFields* fields = nullptr) {
  HostRegistrationFields local_fields;
  HostRegistrationFields& host_fields = fields ? *fields : local_fields;
  for (const RegistrationTerm& t : terms) host_fields.host_map(t.map_j);  // copies are not timed
  const auto start = std::chrono::steady_clock::now();
  ceres::Problem problem;
  add_constraints_4dof(graph, &problem);
  for (const RegistrationTerm& t : terms) {
    const Stream stream(t.points_i->points.device());
    std::vector<RegistrationPoint> points = t.points_i->points.to_host(stream);
    if (points.empty()) continue;
    const RegistrationDistanceLookup lookup =
        make_registration_lookup(host_fields.host_map(t.map_j), t.residual);
    problem.AddResidualBlock(
        new RegistrationPairCost(std::move(points), lookup, t.residual, t.residual_sigma), nullptr,
        &graph->poses[t.vertex_i].x, &graph->poses[t.vertex_j].x);
  }
  hold_fixed_vertex_4dof(graph, &problem);
  return finish(&problem, o, start);
}

}  // namespace ceres_oracle
}  // namespace backend
}  // namespace covox
#endif  // COVOX_HAVE_CERES

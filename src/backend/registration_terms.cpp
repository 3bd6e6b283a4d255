#include "covoxslam/backend/registration_terms.h"

#include <cmath>
#include <string>

#include "covoxslam/backend/internal/registration_ops.h"
#include "covoxslam/core/error.h"

namespace covox {
namespace backend {

void validate_registration_terms(const std::vector<RegistrationTerm>& terms, int32_t vertex_count,
                                 Device device) {
  for (size_t k = 0; k < terms.size(); ++k) {
    const RegistrationTerm& t = terms[k];
    const std::string what = "registration term " + std::to_string(k) + " (" +
                             std::to_string(t.vertex_i) + " -> " + std::to_string(t.vertex_j) + ")";
    if (t.vertex_i < 0 || t.vertex_i >= vertex_count || t.vertex_j < 0 ||
        t.vertex_j >= vertex_count) {
      throw Error(what + ": a vertex is out of range (the graph has " +
                  std::to_string(vertex_count) + " poses)");
    }
    if (t.vertex_i == t.vertex_j) throw Error(what + ": joins a vertex to itself");
    if (t.points_i == nullptr || t.map_j == nullptr)
      throw Error(what + ": points_i and map_j must be set");
    if (t.points_i->points.device() != device || t.map_j->device() != device) {
      throw Error(what + ": its points live on " +
                  std::string(to_string(t.points_i->points.device())) + " and its map on " +
                  to_string(t.map_j->device()) + ", but the solve runs on " + to_string(device));
    }
    if (!(t.residual_sigma > 0.0 && std::isfinite(t.residual_sigma))) {
      throw Error(what + ": residual_sigma must be finite and > 0, got " +
                  std::to_string(t.residual_sigma));
    }
    try {
      validate_registration_residual_config(t.residual);
    } catch (const Error& error) {
      throw Error(what + ": " + error.what());
    }
  }
}

double registration_terms_cost(const PoseGraph4Dof& graph,
                               const std::vector<RegistrationTerm>& terms) {
  double cost = 0.0;
  for (const RegistrationTerm& t : terms) {
    // Plain residuals, then the term's sigma and robust loss on the host.
    RegistrationResidualConfig plain = t.residual;
    plain.loss = RobustLoss::kNone;
    const RobustLossParams robust{t.residual.loss, t.residual.loss_scale};
    const auto residuals = evaluate_registration_residuals(
        *t.points_i, *t.map_j, graph.poses.at(t.vertex_i), graph.poses.at(t.vertex_j), plain);
    for (const RegistrationResidual& r : residuals) {
      if (!r.valid) continue;
      const double scaled = r.residual / t.residual_sigma;
      double rho = 0.0, rho_prime = 0.0;
      robust.evaluate(scaled * scaled, &rho, &rho_prime);
      cost += 0.5 * rho;
    }
  }
  return cost;
}

}  // namespace backend
}  // namespace covox

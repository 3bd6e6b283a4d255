#pragma once
// Dense registration terms inside the 4-DoF pose graph (voxgraph's formulation: the registration
// residuals of every overlapping pair are part of the optimisation, not summarised into one
// relative-pose constraint first). A term joins vertex i (whose registration points are used) and
// vertex j (whose distance field is looked up), with registration.h's residual and robust loss
// per point. The solver evaluates all terms in one launch, reduces them per pair into the 4x4
// blocks H_ii, H_ij, H_jj, g_i, g_j (IRLS: H = sum rho' J^T J, g = sum rho' J^T r) and adds them
// to the block-sparse normal equations beside the ordinary constraints. Its cost is
// sum 0.5 rho(r^2) over the points that fall inside submap j's observed field.
#include <cstdint>
#include <vector>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/registration.h"

namespace covox {
namespace backend {

struct RegistrationTerm {
  int32_t vertex_i = 0;                          // the points' submap
  int32_t vertex_j = 0;                          // the field's submap
  const RegistrationPoints* points_i = nullptr;  // not owned; on the solver's device
  const map::TsdfMap* map_j = nullptr;           // not owned; on the solver's device; ESDF computed
  RegistrationResidualConfig residual;
  // The residuals (and Jacobians) are divided by this before the robust loss: the noise of one
  // point's residual in registration.h's units (metres times sqrt(TSDF weight)), which sets how
  // strongly registration counts against odometry. 1 keeps registration.h's scale.
  double residual_sigma = 1.0;
};

// Throws covox::Error naming the term when a vertex is out of range, i == j, a pointer is null,
// the points or the map live on another device than `device`, the residual config is invalid, or
// residual_sigma is not finite and positive.
void validate_registration_terms(const std::vector<RegistrationTerm>& terms, int32_t vertex_count,
                                 Device device);

// Host reference of the terms' cost at `graph.poses` (one evaluate_registration_residuals call per
// term, summed on the host): for tests and tools.
double registration_terms_cost(const PoseGraph4Dof& graph,
                               const std::vector<RegistrationTerm>& terms);

}  // namespace backend
}  // namespace covox

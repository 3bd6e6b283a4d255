#pragma once
// Levenberg-Marquardt + PCG over a pose-graph model, written once for both backends. Host code
// only orchestrates: every per-constraint, per-block and per-entry step is a parallel_for or a
// reduction on the device (normal_equations_impl.h); the host reads back LM's scalars (costs,
// the model's decrease, norms) to steer it, while CG's stay on the device
// (conjugate_gradient_impl.h).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#include "covoxslam/backend/internal/block_sparse_structure.h"
#include "covoxslam/backend/internal/conjugate_gradient_impl.h"
#include "covoxslam/backend/internal/normal_equations_impl.h"
#include "covoxslam/backend/internal/pose_graph_solver_ops.h"
#include "covoxslam/backend/internal/registration_terms_workspace.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"

namespace covox {
namespace backend {

// Everything one solve needs on the device, allocated once up front. Registration terms
// (4-DoF only) enter the block structure after the constraints: term t is edge
// constraints.size() + t, from vertex_i to vertex_j.
template <class Backend, class Model>
class PoseGraphWorkspace {
 public:
  static constexpr int D = Model::kDim;
  static constexpr int DD = D * D;
  static constexpr bool kHasRegistration = std::is_same<Model, FourDofModel>::value;
  using Pose = typename Model::Pose;

  PoseGraphWorkspace(const PoseGraph<Model>& graph, const Stream& stream,
                     const std::vector<RegistrationTerm>& registration = {})
      : stream_(stream),
        vertex_count_(static_cast<int32_t>(graph.poses.size())),
        constraint_count_(static_cast<int64_t>(graph.constraints.size())) {
    const Device device = Backend::kDevice;
    std::vector<std::pair<int32_t, int32_t>> edges;
    edges.reserve(graph.constraints.size() + registration.size());
    for (const auto& c : graph.constraints) edges.emplace_back(c.from, constraint_to(c));
    if (!registration.empty()) {
      if constexpr (kHasRegistration) {
        for (const RegistrationTerm& t : registration) edges.emplace_back(t.vertex_i, t.vertex_j);
        registration_ = std::make_unique<RegistrationTermsWorkspace<Backend>>(registration, stream);
      } else {
        throw Error("pose graph: registration terms need the 4-DoF model");
      }
    }
    const BlockSparseStructure s =
        build_block_sparse_structure(edges, vertex_count_, graph.fixed_vertex);
    off_block_count_ = s.off_block_count();

    poses = Buffer<Pose>::from_host(device, graph.poses, stream);
    candidate = Buffer<Pose>(device, graph.poses.size());
    constraints = Buffer<typename Model::Constraint>::from_host(device, graph.constraints, stream);
    const size_t e = graph.constraints.size(), n = graph.poses.size();
    residuals = Buffer<double>(device, e * D);
    jac_from = Buffer<double>(device, e * DD);
    jac_to = Buffer<double>(device, e * DD);
    costs = Buffer<double>(device, e);
    hessian_diag = Buffer<double>(device, n * DD);
    hessian_off = Buffer<double>(device, static_cast<size_t>(off_block_count_) * DD);
    gradient = Buffer<double>(device, n * D);
    damping = Buffer<double>(device, n * D);
    preconditioner = Buffer<double>(device, n * DD);
    for (Buffer<double>* v : {&step, &cg_r, &cg_z, &cg_p, &cg_q})
      *v = Buffer<double>(device, n * D);
    cg_state = Buffer<CgState>(device, 1);
    std::vector<int64_t> iota(n * D);
    for (size_t i = 0; i < iota.size(); ++i) iota[i] = static_cast<int64_t>(i);
    indices = Buffer<int64_t>::from_host(device, iota, stream);
    diag_offsets = Buffer<int32_t>::from_host(device, s.diag_offsets, stream);
    diag_terms = Buffer<int32_t>::from_host(device, s.diag_terms, stream);
    off_offsets = Buffer<int32_t>::from_host(device, s.off_offsets, stream);
    off_terms = Buffer<int32_t>::from_host(device, s.off_terms, stream);
    row_offsets = Buffer<int32_t>::from_host(device, s.row_offsets, stream);
    row_entries = Buffer<int32_t>::from_host(device, s.row_entries, stream);
    row_columns = Buffer<int32_t>::from_host(device, s.row_columns, stream);
    chain_blocks = Buffer<int32_t>::from_host(device, s.chain_blocks, stream);
    view_ = StructureView{vertex_count_,      s.fixed_vertex,
                          off_block_count_,   diag_offsets.data(),
                          diag_terms.data(),  off_offsets.data(),
                          off_terms.data(),   row_offsets.data(),
                          row_entries.data(), row_columns.data(),
                          constraint_count_,  registration_ ? registration_->term_sums() : nullptr};
  }

  const StructureView& view() const { return view_; }
  int64_t unknowns() const { return static_cast<int64_t>(vertex_count_) * D; }

  // Residuals, Jacobians (and the registration terms' sums) and the cost at `poses`.
  double evaluate() {
    evaluate_constraints<Model>(Backend{}, stream_, constraints.data(), constraint_count_,
                                poses.data(), residuals.data(), jac_from.data(), jac_to.data(),
                                costs.data());
    double cost = sum_costs();
    if constexpr (kHasRegistration) {
      if (registration_) cost += registration_->evaluate(poses.data());
    }
    return cost;
  }
  double cost_at_candidate() {
    constraint_costs<Model>(Backend{}, stream_, constraints.data(), constraint_count_,
                            candidate.data(), costs.data());
    double cost = sum_costs();
    if constexpr (kHasRegistration) {
      if (registration_) cost += registration_->cost(candidate.data());
    }
    return cost;
  }
  bool has_terms() const {
    return constraint_count_ > 0 || (registration_ && registration_->term_count() > 0);
  }
  int64_t registration_points() const { return registration_ ? registration_->point_count() : 0; }
  int64_t registration_points_used() const {
    return registration_ ? registration_->used_points() : 0;
  }
  void assemble() {
    assemble_diagonal_and_gradient<D>(Backend{}, stream_, view_, jac_from.data(), jac_to.data(),
                                      residuals.data(), hessian_diag.data(), gradient.data());
    assemble_off_diagonal<D>(Backend{}, stream_, view_, jac_from.data(), jac_to.data(),
                             hessian_off.data());
  }
  double max_abs_gradient() {
    return max_abs(Backend{}, stream_, indices.data(), unknowns(), gradient.data());
  }

  // Solves (H + damping) step = -g with PCG (conjugate_gradient_impl.h); returns the iterations
  // used.
  int solve_damped(double radius, const PoseGraphSolverOptions& options) {
    const int64_t n = unknowns();
    const Backend b{};
    damping_and_preconditioner<D>(b, stream_, vertex_count_, hessian_diag.data(), radius,
                                  options.min_diagonal, options.max_diagonal, damping.data(),
                                  preconditioner.data());
    const bool chain = options.preconditioner == PcgPreconditioner::kOdometryChain;
    const int32_t segment =
        options.chain_segment_vertices > 0
            ? std::min<int32_t>(options.chain_segment_vertices, std::max<int32_t>(vertex_count_, 1))
            : std::max<int32_t>(vertex_count_, 1);
    if (chain) {
      factorize_chain<D>(b, stream_, vertex_count_, segment, hessian_diag.data(),
                         hessian_off.data(), damping.data(), chain_blocks.data(),
                         preconditioner.data());
    }
    const auto precondition = [&](const double* in, double* out) {
      if (chain) {
        apply_chain_preconditioner<D>(b, stream_, vertex_count_, segment, hessian_off.data(),
                                      chain_blocks.data(), preconditioner.data(), in, out);
      } else {
        apply_preconditioner<D>(b, stream_, vertex_count_, preconditioner.data(), in, out);
      }
    };
    // x = 0, r = -g.
    double* x = step.data();
    double* r = cg_r.data();
    const double* g = gradient.data();
    parallel_for(b, stream_, n, [=] COVOX_HD(int64_t i) {
      x[i] = 0.0;
      r[i] = -g[i];
    });
    CgState* state = cg_state.data();
    dot_into(b, stream_, indices.data(), n, r, r, &state->rr);
    cg_start(b, stream_, state);
    precondition(r, cg_z.data());
    cg_p.copy_from(cg_z, stream_);
    dot_into(b, stream_, indices.data(), n, r, cg_z.data(), &state->rz);
    // Iterations are enqueued in rounds; the state is read back (a wait) once per round.
    constexpr int kIterationsPerRound = 8;
    CgState read_back;
    for (int enqueued = 0; enqueued < options.pcg_max_iterations;) {
      const int round = std::min(kIterationsPerRound, options.pcg_max_iterations - enqueued);
      for (int k = 0; k < round; ++k) {
        multiply_normal_matrix<D>(b, stream_, view_, hessian_diag.data(), hessian_off.data(),
                                  damping.data(), cg_p.data(), cg_q.data());
        dot_into(b, stream_, indices.data(), n, cg_p.data(), cg_q.data(), &state->pq);
        cg_update(b, stream_, n, state, cg_p.data(), cg_q.data(), x, r);
        dot_into(b, stream_, indices.data(), n, r, r, &state->rr);
        precondition(r, cg_z.data());
        dot_into(b, stream_, indices.data(), n, r, cg_z.data(), &state->rz_next);
        cg_advance(b, stream_, options.pcg_relative_tolerance, state);
        cg_direction(b, stream_, n, state, cg_z.data(), cg_p.data());
      }
      enqueued += round;
      read_back = cg_state.to_host(stream_)[0];
      if (read_back.stopped) break;
    }
    return read_back.iterations;
  }

  // The decrease of the undamped quadratic model: -(g.step + 0.5 step.H.step).
  double model_decrease() {
    const int64_t n = unknowns();
    multiply_normal_matrix<D>(Backend{}, stream_, view_, hessian_diag.data(), hessian_off.data(),
                              nullptr, step.data(), cg_q.data());
    const double g_step = dot(Backend{}, stream_, indices.data(), n, gradient.data(), step.data());
    const double step_h_step = dot(Backend{}, stream_, indices.data(), n, step.data(), cg_q.data());
    return -(g_step + 0.5 * step_h_step);
  }
  double step_norm() {
    return std::sqrt(dot(Backend{}, stream_, indices.data(), unknowns(), step.data(), step.data()));
  }
  double pose_norm() {
    return std::sqrt(transform_reduce(
        Backend{}, stream_, poses.data(), vertex_count_,
        [] COVOX_HD(const Pose& p) { return Model::squared_norm(p); }, 0.0,
        thrust::plus<double>()));
  }
  void make_candidate() {
    plus_poses<Model>(Backend{}, stream_, vertex_count_, poses.data(), step.data(),
                      candidate.data());
  }
  void accept_candidate() { std::swap(poses, candidate); }

  Buffer<Pose> poses, candidate;
  Buffer<typename Model::Constraint> constraints;
  Buffer<double> residuals, jac_from, jac_to, costs;
  Buffer<double> hessian_diag, hessian_off, gradient, damping, preconditioner;
  Buffer<double> step, cg_r, cg_z, cg_p, cg_q;
  Buffer<CgState> cg_state;
  Buffer<int64_t> indices;
  Buffer<int32_t> diag_offsets, diag_terms, off_offsets, off_terms, row_offsets, row_entries,
      row_columns;
  Buffer<int32_t> chain_blocks;

 private:
  double sum_costs() {
    return reduce(Backend{}, stream_, costs.data(), constraint_count_, 0.0, thrust::plus<double>());
  }

  const Stream& stream_;
  int32_t vertex_count_;
  int64_t constraint_count_;
  int64_t off_block_count_ = 0;
  std::unique_ptr<RegistrationTermsWorkspace<Backend>> registration_;
  StructureView view_{};
};

template <class Backend, class Model>
PoseGraphSolverSummary solve_pose_graph_with_terms(
    PoseGraph<Model>* graph, const std::vector<RegistrationTerm>& registration,
    const PoseGraphSolverOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  PoseGraphSolverSummary summary;
  const Stream stream(Backend::kDevice);
  PoseGraphWorkspace<Backend, Model> w(*graph, stream, registration);
  double cost = w.evaluate();
  summary.initial_cost = summary.final_cost = cost;
  summary.registration_points = w.registration_points();
  if (!w.has_terms()) {
    summary.termination = PoseGraphTermination::kNoConstraints;
    return summary;
  }
  double radius = options.initial_trust_region_radius;
  double decrease_factor = 2.0;
  summary.termination = PoseGraphTermination::kMaxIterations;
  bool need_assembly = true;
  while (summary.iterations < options.max_iterations) {
    if (need_assembly) {
      w.assemble();
      if (w.max_abs_gradient() <= options.gradient_tolerance) {
        summary.termination = PoseGraphTermination::kGradientTolerance;
        break;
      }
      need_assembly = false;
    }
    ++summary.iterations;
    summary.pcg_iterations += w.solve_damped(radius, options);
    const double predicted = w.model_decrease();
    const double step_norm = w.step_norm();
    if (step_norm <= options.parameter_tolerance * (w.pose_norm() + options.parameter_tolerance)) {
      summary.termination = PoseGraphTermination::kParameterTolerance;
      break;
    }
    w.make_candidate();
    const double candidate_cost = w.cost_at_candidate();
    const double actual = cost - candidate_cost;
    const double rho = predicted > 0.0 ? actual / predicted : -1.0;
    if (std::isfinite(candidate_cost) && rho > options.min_relative_decrease) {
      w.accept_candidate();
      ++summary.accepted_steps;
      const double new_cost = w.evaluate();  // also refreshes the Jacobians at the new poses
      const double t = 2.0 * rho - 1.0;
      radius =
          std::min(options.max_trust_region_radius, radius / std::max(1.0 / 3.0, 1.0 - t * t * t));
      decrease_factor = 2.0;
      need_assembly = true;
      const double old_cost = cost;
      cost = new_cost;
      if (old_cost - new_cost <= options.function_tolerance * old_cost) {
        summary.termination = PoseGraphTermination::kFunctionTolerance;
        break;
      }
    } else {
      radius /= decrease_factor;
      decrease_factor *= 2.0;
      if (radius < options.min_trust_region_radius) {
        summary.termination = PoseGraphTermination::kTrustRegionCollapsed;
        break;
      }
    }
  }
  summary.final_cost = cost;
  graph->poses = w.poses.to_host(stream);
  summary.solve_time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // After the clock: a diagnostic read-back, not part of the solve.
  summary.registration_points_used = w.registration_points_used();
  return summary;
}

template <class Backend, class Model>
PoseGraphSolverSummary solve_pose_graph_on(Backend, PoseGraph<Model>* graph,
                                           const PoseGraphSolverOptions& options) {
  return solve_pose_graph_with_terms<Backend, Model>(graph, {}, options);
}

template <class Backend>
PoseGraphSolverSummary solve_pose_graph_on(Backend, PoseGraph4Dof* graph,
                                           const std::vector<RegistrationTerm>& terms,
                                           const PoseGraphSolverOptions& options) {
  return solve_pose_graph_with_terms<Backend, FourDofModel>(graph, terms, options);
}

template <class Backend, class Model>
PoseGraphEvaluation evaluate_pose_graph_with_terms(
    const PoseGraph<Model>& graph, const std::vector<RegistrationTerm>& registration) {
  const Stream stream(Backend::kDevice);
  PoseGraphWorkspace<Backend, Model> w(graph, stream, registration);
  PoseGraphEvaluation out;
  out.dimension = Model::kDim;
  out.cost = w.evaluate();
  w.assemble();
  out.residuals = w.residuals.to_host(stream);
  out.jacobians_from = w.jac_from.to_host(stream);
  out.jacobians_to = w.jac_to.to_host(stream);
  out.gradient = w.gradient.to_host(stream);
  out.hessian_diagonal_blocks = w.hessian_diag.to_host(stream);
  return out;
}

template <class Backend, class Model>
PoseGraphEvaluation evaluate_pose_graph_on(Backend, const PoseGraph<Model>& graph) {
  return evaluate_pose_graph_with_terms<Backend, Model>(graph, {});
}

template <class Backend>
PoseGraphEvaluation evaluate_pose_graph_on(Backend, const PoseGraph4Dof& graph,
                                           const std::vector<RegistrationTerm>& terms) {
  return evaluate_pose_graph_with_terms<Backend, FourDofModel>(graph, terms);
}

#define COVOX_INSTANTIATE_POSE_GRAPH_SOLVER(Backend, Model)                    \
  template PoseGraphSolverSummary solve_pose_graph_on<Backend, Model>(         \
      Backend, PoseGraph<Model>*, const PoseGraphSolverOptions&);              \
  template PoseGraphEvaluation evaluate_pose_graph_on<Backend, Model>(Backend, \
                                                                      const PoseGraph<Model>&);

// The 4-DoF entry points with registration terms, once per backend.
#define COVOX_INSTANTIATE_POSE_GRAPH_REGISTRATION(Backend)           \
  template PoseGraphSolverSummary solve_pose_graph_on<Backend>(      \
      Backend, PoseGraph4Dof*, const std::vector<RegistrationTerm>&, \
      const PoseGraphSolverOptions&);                                \
  template PoseGraphEvaluation evaluate_pose_graph_on<Backend>(      \
      Backend, const PoseGraph4Dof&, const std::vector<RegistrationTerm>&);

}  // namespace backend
}  // namespace covox

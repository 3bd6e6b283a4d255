#pragma once
// The optimisation policy of the submap pose graph in one place: around the plain LM + PCG solve,
// the re-linearisation of absolute constraints, the robust loss's reweighting rounds, the
// consistency gate and the odometry's noise estimation, all within one solve budget per
// optimisation. docs/design.md ("Pose graph") describes each step.
#include <cstdint>
#include <functional>
#include <vector>

#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/pipeline/revisit_drift.h"
#include "covoxslam/pipeline/submap_pose_graph.h"

namespace covox {
namespace pipeline {

struct SlamConfig;

// The graph an optimisation works on, owned elsewhere (the SLAM system) behind the owner's lock:
// each call takes the lock for its own duration, so the solver itself runs without it.
class OptimizedGraph {
 public:
  struct SolverInput {
    SubmapPoseGraph::BackendGraph graph;
    std::vector<backend::RegistrationTerm> terms;  // dense registration terms (kJoint)
    bool has_absolute = false;                     // GNSS or height constraints present
  };
  virtual ~OptimizedGraph() = default;
  // Runs `change` on the pose graph under the owner's lock.
  virtual void edit(const std::function<void(SubmapPoseGraph&)>& change) = 0;
  // The graph as the solver takes it; throws when it cannot be built.
  virtual SolverInput solver_input() = 0;
  // Stores a solved graph: the submaps' poses follow it.
  virtual void apply(const SubmapPoseGraph::BackendGraph& solved,
                     const backend::PoseGraphSolverSummary& summary, double solve_s) = 0;
  // The odometry's path from the first submap to each submap, in the graph's node order.
  virtual std::vector<double> path_at_node_m() = 0;
};

// What one optimisation did.
struct OptimizationReport {
  int64_t solves = 0;         // solves that succeeded (each applied to the graph)
  int64_t failed_solves = 0;  // solves that threw (logged); the optimisation stops at the first
  int64_t budget = 0;         // the solves it was allowed
  bool budget_exhausted = false;
  // The consistency gate ran to its end: registrations it set aside.
  bool gate_finished = false;
  int64_t set_aside = 0;
  // The odometry's noise estimate (estimate_odometry_noise), when it ran: the drift per metre the
  // solve used and the revisits' drift that bounded it.
  bool noise_estimated = false;
  double odometry_drift_m_per_m = 0.0;
  double odometry_drift_deg_per_m = 0.0;
  RevisitDrift revisits;
};

class GraphOptimizer {
 public:
  // Reads the pose_graph and registration.gate parameters of `config` (copied).
  explicit GraphOptimizer(const SlamConfig& config);
  // Optimises `graph` after `new_submaps` submaps entered it since the previous optimisation
  // (at least 1 is assumed): budget pose_graph.max_solves_per_new_submap solves per new submap.
  // Once the budget is spent the optimisation stops with the latest solution kept.
  OptimizationReport optimize(OptimizedGraph& graph, int64_t new_submaps);

 private:
  class Run;  // one optimisation's state (graph, budget, report)

  double max_residual_m_;  // registration.gate.max_residual_vox x map.voxel_size_m
  double worst_fraction_;
  double loss_scale_sigmas_;
  bool estimate_noise_;
  double drift_m_per_m_, drift_deg_per_m_;
  double min_drift_m_per_m_, min_drift_deg_per_m_;
  double revisit_min_path_m_;
  int64_t solves_per_new_submap_;
  Device device_;
  backend::PoseGraphSolverOptions solver_;
};

}  // namespace pipeline
}  // namespace covox

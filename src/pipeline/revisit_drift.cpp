#include "covoxslam/pipeline/revisit_drift.h"

#include <cmath>
#include <string>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {
namespace {

// Each node's pose in the frame of its odometry chain's first node (the odometry constraints
// composed), and which chain it is on: a node without an odometry constraint from the node before
// it starts a new chain.
struct OdometryChains {
  std::vector<backend::Pose4Dof> pose_in_chain;
  std::vector<int64_t> chain_of_node;
};

OdometryChains compose_odometry_chains(const SubmapPoseGraph& graph) {
  const size_t n = graph.size();
  std::vector<const SubmapConstraint*> link_into(n, nullptr);
  for (const SubmapConstraint& c : graph.constraints()) {
    if (c.kind != SubmapConstraintKind::kOdometry) continue;
    const int64_t from = graph.index_of(c.from_submap), to = graph.index_of(c.to_submap);
    if (from >= 0 && to == from + 1) link_into[static_cast<size_t>(to)] = &c;
  }
  OdometryChains chains;
  chains.pose_in_chain.resize(n);
  chains.chain_of_node.resize(n, 0);
  for (size_t k = 1; k < n; ++k) {
    if (link_into[k] == nullptr) {
      chains.chain_of_node[k] = chains.chain_of_node[k - 1] + 1;
      continue;  // pose_in_chain stays the identity: the start of a chain
    }
    chains.chain_of_node[k] = chains.chain_of_node[k - 1];
    chains.pose_in_chain[k] = compose(chains.pose_in_chain[k - 1], link_into[k]->measurement);
  }
  return chains;
}

}  // namespace

RevisitDrift estimate_revisit_drift(const SubmapPoseGraph& graph,
                                    const std::vector<double>& path_at_node_m, double min_path_m) {
  if (path_at_node_m.size() != graph.size()) {
    throw Error("estimate_revisit_drift: " + std::to_string(path_at_node_m.size()) +
                " path lengths for a graph of " + std::to_string(graph.size()) +
                " submaps; give one per submap");
  }
  if (!(std::isfinite(min_path_m) && min_path_m > 0.0))
    throw Error("estimate_revisit_drift: min_path_m must be positive, got " +
                std::to_string(min_path_m));
  const OdometryChains chains = compose_odometry_chains(graph);
  double sum_translation_sq = 0.0, sum_yaw_sq = 0.0, sum_path_sq = 0.0;
  RevisitDrift drift;
  for (const SubmapConstraint& c : graph.constraints()) {
    if (c.kind != SubmapConstraintKind::kRegistration || !c.active) continue;
    const int64_t from = graph.index_of(c.from_submap), to = graph.index_of(c.to_submap);
    if (from < 0 || to < 0) continue;
    const size_t a = static_cast<size_t>(from), b = static_cast<size_t>(to);
    if (chains.chain_of_node[a] != chains.chain_of_node[b]) continue;
    const double path_m = std::abs(path_at_node_m[b] - path_at_node_m[a]);
    if (!(path_m >= min_path_m)) continue;
    const backend::Pose4Dof odometry =
        relative_pose_4dof(chains.pose_in_chain[a], chains.pose_in_chain[b]);
    const double dx = c.measurement.x - odometry.x, dy = c.measurement.y - odometry.y,
                 dz = c.measurement.z - odometry.z;
    const double dyaw =
        std::remainder(c.measurement.yaw - odometry.yaw, 2.0 * 3.14159265358979323846);
    sum_translation_sq += dx * dx + dy * dy + dz * dz;
    sum_yaw_sq += dyaw * dyaw;
    sum_path_sq += path_m * path_m;
    ++drift.revisits;
  }
  if (drift.revisits == 0) return drift;
  drift.m_per_m = std::sqrt(sum_translation_sq / sum_path_sq);
  drift.rad_per_m = std::sqrt(sum_yaw_sq / sum_path_sq);
  return drift;
}

}  // namespace pipeline
}  // namespace covox

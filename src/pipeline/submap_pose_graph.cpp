#include "covoxslam/pipeline/submap_pose_graph.h"

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <utility>

#include "covoxslam/backend/pose_graph_models.h"
#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

namespace {

double wrap_to_pi(double angle) { return std::atan2(std::sin(angle), std::cos(angle)); }

bool finite_pose(const backend::Pose4Dof& pose) {
  return std::isfinite(pose.x) && std::isfinite(pose.y) && std::isfinite(pose.z) &&
         std::isfinite(pose.yaw);
}

}  // namespace

const char* to_string(SubmapConstraintKind kind) {
  switch (kind) {
    case SubmapConstraintKind::kOdometry:
      return "odometry";
    case SubmapConstraintKind::kRegistration:
      return "registration";
    case SubmapConstraintKind::kLoopClosure:
      return "loop closure";
    case SubmapConstraintKind::kAbsolutePosition:
      return "absolute position";
    case SubmapConstraintKind::kHeight:
      return "height";
    case SubmapConstraintKind::kGaugeAnchor:
      return "gauge anchor";
  }
  return "unknown";
}

backend::Pose4Dof compose(const backend::Pose4Dof& a, const backend::Pose4Dof& b) {
  const double c = std::cos(a.yaw), s = std::sin(a.yaw);
  backend::Pose4Dof result;
  result.x = a.x + c * b.x - s * b.y;
  result.y = a.y + s * b.x + c * b.y;
  result.z = a.z + b.z;
  result.yaw = wrap_to_pi(a.yaw + b.yaw);
  return result;
}

void SubmapPoseGraph::add_submap(int64_t id, const backend::Pose4Dof& pose, bool loaded) {
  if (!finite_pose(pose))
    throw Error("submap pose graph: the pose of submap " + std::to_string(id) + " is not finite");
  if (!nodes_.empty() && id <= nodes_.back().id) {
    throw Error("submap pose graph: submap ids must increase, got " + std::to_string(id) +
                " after " + std::to_string(nodes_.back().id));
  }
  if (loaded && !nodes_.empty() && !nodes_.back().loaded) {
    throw Error("submap pose graph: loaded submap " + std::to_string(id) + " after a mapped one");
  }
  nodes_.push_back(SubmapPoseGraphNode{id, pose, loaded});
}

int64_t SubmapPoseGraph::index_of(int64_t id) const {
  auto it = std::lower_bound(
      nodes_.begin(), nodes_.end(), id,
      [](const SubmapPoseGraphNode& node, int64_t value) { return node.id < value; });
  if (it == nodes_.end() || it->id != id) return -1;
  return static_cast<int64_t>(it - nodes_.begin());
}

void SubmapPoseGraph::add_constraint(const SubmapConstraint& constraint) {
  const std::string what =
      std::string("submap pose graph: ") + to_string(constraint.kind) + " constraint";
  const int64_t from = index_of(constraint.from_submap);
  if (from < 0)
    throw Error(what + " names unknown submap " + std::to_string(constraint.from_submap));
  if (!constraint.information.allFinite() || !finite_pose(constraint.measurement) ||
      !constraint.lever_arm_m.allFinite()) {
    throw Error(what + " has a non-finite measurement or information");
  }
  if (!constraint.is_absolute()) {
    const int64_t to = index_of(constraint.to_submap);
    if (to < 0) throw Error(what + " names unknown submap " + std::to_string(constraint.to_submap));
    if (to == from)
      throw Error(what + " joins submap " + std::to_string(constraint.from_submap) + " to itself");
    if (nodes_[static_cast<size_t>(to)].loaded) {
      throw Error(what + " ends in loaded submap " + std::to_string(constraint.to_submap) +
                  " (relative constraints must start at the loaded map)");
    }
  }
  constraints_.push_back(constraint);
}

void SubmapPoseGraph::set_active(size_t index, bool active) {
  if (index >= constraints_.size()) {
    throw Error("submap pose graph: constraint " + std::to_string(index) + " does not exist (" +
                std::to_string(constraints_.size()) + " constraints)");
  }
  constraints_[index].active = active;
}

void SubmapPoseGraph::set_weight(size_t index, double weight) {
  if (index >= constraints_.size() || !(weight > 0.0 && weight <= 1.0)) {
    throw Error("submap pose graph: no weight " + std::to_string(weight) + " for constraint " +
                std::to_string(index) + " (" + std::to_string(constraints_.size()) +
                " constraints; weights lie in (0, 1])");
  }
  constraints_[index].weight = weight;
}

void SubmapPoseGraph::set_variance_factors(SubmapConstraintKind kind,
                                           const VarianceFactors& factors) {
  if (kind != SubmapConstraintKind::kOdometry && kind != SubmapConstraintKind::kRegistration) {
    throw Error(std::string("submap pose graph: no variance factors for ") + to_string(kind) +
                " constraints");
  }
  if (!(std::isfinite(factors.translation) && factors.translation > 0.0 &&
        std::isfinite(factors.yaw) && factors.yaw > 0.0)) {
    throw Error("submap pose graph: variance factors must be positive, got " +
                std::to_string(factors.translation) + " and " + std::to_string(factors.yaw));
  }
  (kind == SubmapConstraintKind::kOdometry ? odometry_factors_ : registration_factors_) = factors;
}

VarianceFactors SubmapPoseGraph::variance_factors(SubmapConstraintKind kind) const {
  if (kind == SubmapConstraintKind::kOdometry) return odometry_factors_;
  if (kind == SubmapConstraintKind::kRegistration) return registration_factors_;
  return VarianceFactors();
}

Eigen::Matrix4d SubmapPoseGraph::scaled_information(const SubmapConstraint& c) const {
  const VarianceFactors f = variance_factors(c.kind);
  // Factors of 1 leave the information bit for bit as it was given.
  if (f.translation == 1.0 && f.yaw == 1.0) return c.information;
  const double t = 1.0 / std::sqrt(f.translation), y = 1.0 / std::sqrt(f.yaw);
  const Eigen::Vector4d scale(t, t, t, y);
  return scale.asDiagonal() * c.information * scale.asDiagonal();
}

namespace {

// The whitened residual and Jacobians of one backend constraint, and the columns of its vertices
// among the free unknowns (-1: held or absent).
struct WhitenedTerm {
  double f[4];
  double jac_i[16];
  double jac_j[16];
  int64_t column_i = -1;
  int64_t column_j = -1;
};

WhitenedTerm whitened_term(const backend::PoseGraph4Dof& graph, size_t k,
                           const std::vector<int64_t>& column_of_vertex) {
  WhitenedTerm term;
  const backend::Constraint4Dof& c = graph.constraints[k];
  backend::FourDofModel::evaluate(c, graph.poses.data(), term.f, term.jac_i, term.jac_j);
  term.column_i = column_of_vertex[static_cast<size_t>(c.from)];
  const int32_t to = backend::constraint_to(c);
  if (to != backend::kNoVertex) term.column_j = column_of_vertex[static_cast<size_t>(to)];
  return term;
}

// J^T J of every constraint over the free unknowns (4 per vertex that is not held).
Eigen::SparseMatrix<double> whitened_normal_matrix(const backend::PoseGraph4Dof& graph,
                                                   const std::vector<int64_t>& column_of_vertex,
                                                   int64_t unknowns) {
  std::vector<Eigen::Triplet<double>> entries;
  for (size_t k = 0; k < graph.constraints.size(); ++k) {
    const WhitenedTerm t = whitened_term(graph, k, column_of_vertex);
    const int64_t columns[2] = {t.column_i, t.column_j};
    const double* jacobians[2] = {t.jac_i, t.jac_j};
    for (int a = 0; a < 2; ++a) {
      for (int b = 0; b < 2; ++b) {
        if (columns[a] < 0 || columns[b] < 0) continue;
        for (int r = 0; r < 4; ++r) {
          for (int s = 0; s < 4; ++s) {
            double value = 0.0;
            for (int row = 0; row < 4; ++row)
              value += jacobians[a][row * 4 + r] * jacobians[b][row * 4 + s];
            if (value != 0.0) entries.emplace_back(columns[a] + r, columns[b] + s, value);
          }
        }
      }
    }
  }
  Eigen::SparseMatrix<double> normal(unknowns, unknowns);
  normal.setFromTriplets(entries.begin(), entries.end());
  return normal;
}

// The 4x4 blocks (rows of column r, columns of column c) of Sigma = normal^-1 that the relative
// constraints' rows need: (i, i), (j, j) and (i, j) for each; one solve with four right-hand sides
// per free vertex (its block column of Sigma).
std::map<std::pair<int64_t, int64_t>, Eigen::Matrix4d> covariance_blocks(
    const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>& factor,
    const backend::PoseGraph4Dof& graph, const std::vector<int64_t>& column_of_vertex,
    int64_t unknowns) {
  std::map<int64_t, std::vector<int64_t>>
      partners;  // column -> columns it shares a constraint with
  for (const backend::Constraint4Dof& c : graph.constraints) {
    const int64_t i = column_of_vertex[static_cast<size_t>(c.from)];
    const int32_t to = backend::constraint_to(c);
    const int64_t j = to == backend::kNoVertex ? -1 : column_of_vertex[static_cast<size_t>(to)];
    if (i >= 0) partners[i].push_back(i);
    if (j >= 0) partners[j].push_back(j);
    if (i >= 0 && j >= 0) partners[j].push_back(i);  // block (i, j) from j's block column
  }
  std::map<std::pair<int64_t, int64_t>, Eigen::Matrix4d> blocks;
  for (const auto& entry : partners) {
    const int64_t column = entry.first;
    Eigen::MatrixXd unit = Eigen::MatrixXd::Zero(unknowns, 4);
    unit.block<4, 4>(column, 0).setIdentity();
    const Eigen::MatrixXd block_column = factor.solve(unit);
    for (int64_t row : entry.second) blocks[{row, column}] = block_column.block<4, 4>(row, 0);
  }
  return blocks;
}

}  // namespace

VarianceRatios estimate_variance_ratios(const SubmapPoseGraph& graph) {
  VarianceRatios ratios;
  const SubmapPoseGraph::BackendGraph backend_graph = graph.to_backend_graph();
  const backend::PoseGraph4Dof& g = backend_graph.graph;
  std::vector<int64_t> column_of_vertex(g.poses.size(), -1);
  int64_t unknowns = 0;
  for (size_t v = 0; v < g.poses.size(); ++v) {
    if (static_cast<int32_t>(v) == g.fixed_vertex) continue;
    column_of_vertex[v] = unknowns;
    unknowns += 4;
  }
  if (unknowns == 0) return ratios;
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> factor(
      whitened_normal_matrix(g, column_of_vertex, unknowns));
  if (factor.info() != Eigen::Success) return ratios;
  const std::map<std::pair<int64_t, int64_t>, Eigen::Matrix4d> sigma =
      covariance_blocks(factor, g, column_of_vertex, unknowns);
  // [kind: odometry, registration][component: translation, yaw]
  double sum_sq[2][2] = {{0.0, 0.0}, {0.0, 0.0}}, redundancy[2][2] = {{0.0, 0.0}, {0.0, 0.0}};
  for (size_t k = 0; k < g.constraints.size(); ++k) {
    const SubmapConstraintKind kind =
        graph.constraints()[backend_graph.source_of_constraint[k]].kind;
    if (kind != SubmapConstraintKind::kOdometry && kind != SubmapConstraintKind::kRegistration)
      continue;
    const int group = kind == SubmapConstraintKind::kOdometry ? 0 : 1;
    const WhitenedTerm t = whitened_term(g, k, column_of_vertex);
    const Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> a(t.jac_i), b(t.jac_j);
    // J Sigma J^T over the blocks of the two vertices (a held vertex contributes nothing).
    Eigen::Matrix4d seen = Eigen::Matrix4d::Zero();
    if (t.column_i >= 0) seen += a * sigma.at({t.column_i, t.column_i}) * a.transpose();
    if (t.column_j >= 0) seen += b * sigma.at({t.column_j, t.column_j}) * b.transpose();
    if (t.column_i >= 0 && t.column_j >= 0) {
      const Eigen::Matrix4d cross = a * sigma.at({t.column_i, t.column_j}) * b.transpose();
      seen += cross + cross.transpose();
    }
    for (int row = 0; row < 4; ++row) {
      const int component = row < 3 ? 0 : 1;
      sum_sq[group][component] += t.f[row] * t.f[row];
      redundancy[group][component] += std::min(1.0, std::max(0.0, 1.0 - seen(row, row)));
    }
  }
  VarianceFactors* const out[2] = {&ratios.odometry, &ratios.registration};
  VarianceFactors* const out_redundancy[2] = {&ratios.odometry_redundancy,
                                              &ratios.registration_redundancy};
  for (int group = 0; group < 2; ++group) {
    out_redundancy[group]->translation = redundancy[group][0];
    out_redundancy[group]->yaw = redundancy[group][1];
    if (redundancy[group][0] >= 1.0)
      out[group]->translation = sum_sq[group][0] / redundancy[group][0];
    if (redundancy[group][1] >= 1.0) out[group]->yaw = sum_sq[group][1] / redundancy[group][1];
  }
  return ratios;
}

int set_aside_inconsistent_registrations(SubmapPoseGraph* graph, double max_residual_m,
                                         double worst_fraction) {
  const std::vector<SubmapConstraint>& constraints = graph->constraints();
  const std::vector<SubmapPoseGraphNode>& nodes = graph->nodes();
  std::vector<double> residual_m(constraints.size(), -1.0);  // -1: not judged
  double worst_m = 0.0;
  for (size_t k = 0; k < constraints.size(); ++k) {
    const SubmapConstraint& c = constraints[k];
    if (c.kind != SubmapConstraintKind::kRegistration || !c.active) continue;
    if (c.from_place_recognition) continue;
    const int64_t from = graph->index_of(c.from_submap), to = graph->index_of(c.to_submap);
    if (from < 0 || to < 0) continue;
    // The relative pose at the current poses, in the measurement's convention (from's frame).
    const backend::Pose4Dof& a = nodes[static_cast<size_t>(from)].pose;
    const backend::Pose4Dof& b = nodes[static_cast<size_t>(to)].pose;
    const double cs = std::cos(a.yaw), sn = std::sin(a.yaw);
    const double dx = b.x - a.x, dy = b.y - a.y;
    residual_m[k] =
        std::hypot(cs * dx + sn * dy - c.measurement.x, -sn * dx + cs * dy - c.measurement.y);
    worst_m = std::max(worst_m, residual_m[k]);
  }
  const double cut_m = std::max(max_residual_m, worst_fraction * worst_m);
  int count = 0;
  for (size_t k = 0; k < constraints.size(); ++k) {
    if (residual_m[k] > cut_m) {
      graph->set_active(k, false);
      ++count;
    }
  }
  return count;
}

double reweight_registrations_cauchy(SubmapPoseGraph* graph, double scale_sigmas) {
  const std::vector<SubmapConstraint>& constraints = graph->constraints();
  double largest_change = 0.0;
  for (size_t k = 0; k < constraints.size(); ++k) {
    const SubmapConstraint& c = constraints[k];
    if (c.kind != SubmapConstraintKind::kRegistration || !c.active) continue;
    const int64_t from = graph->index_of(c.from_submap), to = graph->index_of(c.to_submap);
    if (from < 0 || to < 0) continue;
    const backend::Pose4Dof relative =
        relative_pose_4dof(graph->nodes()[static_cast<size_t>(from)].pose,
                           graph->nodes()[static_cast<size_t>(to)].pose);
    const Eigen::Vector4d error(
        relative.x - c.measurement.x, relative.y - c.measurement.y, relative.z - c.measurement.z,
        std::remainder(relative.yaw - c.measurement.yaw, 2.0 * 3.14159265358979323846));
    const double r_sq = std::max(0.0, error.dot(graph->scaled_information(c) * error));
    const double weight = 1.0 / (1.0 + r_sq / (scale_sigmas * scale_sigmas));
    largest_change = std::max(largest_change, std::abs(weight - c.weight));
    graph->set_weight(k, std::max(weight, 1e-12));
  }
  return largest_change;
}

void SubmapPoseGraph::clear() {
  nodes_.clear();
  constraints_.clear();
  odometry_factors_ = VarianceFactors();
  registration_factors_ = VarianceFactors();
}

int64_t SubmapPoseGraph::count(SubmapConstraintKind kind) const {
  return std::count_if(constraints_.begin(), constraints_.end(),
                       [kind](const SubmapConstraint& c) { return c.kind == kind; });
}

SubmapPoseGraph::BackendGraph SubmapPoseGraph::to_backend_graph() const {
  BackendGraph out;
  out.vertex_of_node.resize(nodes_.size());
  out.offset_of_node.resize(nodes_.size());
  int32_t loaded_vertex = backend::kNoVertex;
  backend::Pose4Dof loaded_origin;
  for (size_t k = 0; k < nodes_.size(); ++k) {
    const SubmapPoseGraphNode& node = nodes_[k];
    if (node.loaded && loaded_vertex != backend::kNoVertex) {
      out.vertex_of_node[k] = loaded_vertex;
      out.offset_of_node[k] = compose(backend::inverse_pose_4dof(loaded_origin), node.pose);
      continue;
    }
    const int32_t vertex = static_cast<int32_t>(out.graph.poses.size());
    out.graph.poses.push_back(node.pose);
    out.vertex_of_node[k] = vertex;
    out.offset_of_node[k] = backend::Pose4Dof();
    if (node.loaded) {
      loaded_vertex = vertex;
      loaded_origin = node.pose;
    }
  }

  std::set<int32_t> horizontally_pinned;
  for (size_t index = 0; index < constraints_.size(); ++index) {
    const SubmapConstraint& c = constraints_[index];
    if (!c.active) continue;
    const size_t a = static_cast<size_t>(index_of(c.from_submap));
    const int32_t vertex_a = out.vertex_of_node[a];
    const backend::Pose4Dof& offset_a = out.offset_of_node[a];
    if (c.is_absolute()) {
      // The sensor's lever arm in the vertex frame, then moved with the vertex's current yaw.
      const double co = std::cos(offset_a.yaw), so = std::sin(offset_a.yaw);
      const Eigen::Vector3d lever_in_vertex(
          offset_a.x + co * c.lever_arm_m.x() - so * c.lever_arm_m.y(),
          offset_a.y + so * c.lever_arm_m.x() + co * c.lever_arm_m.y(),
          offset_a.z + c.lever_arm_m.z());
      const double yaw = out.graph.poses[static_cast<size_t>(vertex_a)].yaw;
      const double cv = std::cos(yaw), sv = std::sin(yaw);
      const Eigen::Vector3d origin(
          c.measurement.x - (cv * lever_in_vertex.x() - sv * lever_in_vertex.y()),
          c.measurement.y - (sv * lever_in_vertex.x() + cv * lever_in_vertex.y()),
          c.measurement.z - lever_in_vertex.z());
      if (c.kind == SubmapConstraintKind::kHeight) {
        out.graph.constraints.push_back(
            backend::make_height_constraint_4dof(vertex_a, origin.z(), c.information(2, 2)));
        out.source_of_constraint.push_back(index);
      } else {
        const Eigen::Matrix3d information = c.information.topLeftCorner<3, 3>();
        out.graph.constraints.push_back(
            backend::make_position_constraint_4dof(vertex_a, origin, information));
        out.source_of_constraint.push_back(index);
        if (information.topLeftCorner<2, 2>().trace() > 0.0) horizontally_pinned.insert(vertex_a);
      }
      continue;
    }
    const size_t b = static_cast<size_t>(index_of(c.to_submap));
    const int32_t vertex_b = out.vertex_of_node[b];
    if (vertex_a == vertex_b) continue;  // both in the loaded map: rigid already
    Eigen::Matrix4d rotation = Eigen::Matrix4d::Identity();
    rotation.topLeftCorner<2, 2>() << std::cos(offset_a.yaw), -std::sin(offset_a.yaw),
        std::sin(offset_a.yaw), std::cos(offset_a.yaw);
    const Eigen::Matrix4d information =
        c.weight * (rotation * scaled_information(c) * rotation.transpose());
    out.graph.constraints.push_back(
        backend::make_relative_constraint_4dof(vertex_a, vertex_b, compose(offset_a, c.measurement),
                                               0.5 * (information + information.transpose())));
    out.source_of_constraint.push_back(index);
  }
  if (loaded_vertex != backend::kNoVertex) {
    out.graph.fixed_vertex = loaded_vertex;
  } else {
    out.graph.fixed_vertex = horizontally_pinned.size() >= 2 ? backend::kNoVertex : 0;
  }
  return out;
}

void SubmapPoseGraph::apply_solution(const BackendGraph& solved) {
  if (solved.vertex_of_node.size() != nodes_.size()) {
    throw Error("submap pose graph: the solution is for " +
                std::to_string(solved.vertex_of_node.size()) + " submaps, the graph has " +
                std::to_string(nodes_.size()));
  }
  for (size_t k = 0; k < nodes_.size(); ++k) {
    const backend::Pose4Dof& vertex =
        solved.graph.poses[static_cast<size_t>(solved.vertex_of_node[k])];
    nodes_[k].pose = compose(vertex, solved.offset_of_node[k]);
  }
}

}  // namespace pipeline
}  // namespace covox

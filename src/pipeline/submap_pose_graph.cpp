#include "covoxslam/pipeline/submap_pose_graph.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>

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

int set_aside_inconsistent_registrations(SubmapPoseGraph* graph, double max_residual_m,
                                         double worst_fraction) {
  const std::vector<SubmapConstraint>& constraints = graph->constraints();
  const std::vector<SubmapPoseGraphNode>& nodes = graph->nodes();
  std::vector<double> residual_m(constraints.size(), -1.0);  // -1: not judged
  double worst_m = 0.0;
  for (size_t k = 0; k < constraints.size(); ++k) {
    const SubmapConstraint& c = constraints[k];
    if (c.kind != SubmapConstraintKind::kRegistration || !c.active) continue;
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
    const double r_sq = std::max(0.0, error.dot(c.information * error));
    const double weight = 1.0 / (1.0 + r_sq / (scale_sigmas * scale_sigmas));
    largest_change = std::max(largest_change, std::abs(weight - c.weight));
    graph->set_weight(k, std::max(weight, 1e-12));
  }
  return largest_change;
}

void SubmapPoseGraph::clear() {
  nodes_.clear();
  constraints_.clear();
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
  for (const SubmapConstraint& c : constraints_) {
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
      } else {
        const Eigen::Matrix3d information = c.information.topLeftCorner<3, 3>();
        out.graph.constraints.push_back(
            backend::make_position_constraint_4dof(vertex_a, origin, information));
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
        c.weight * (rotation * c.information * rotation.transpose());
    out.graph.constraints.push_back(
        backend::make_relative_constraint_4dof(vertex_a, vertex_b, compose(offset_a, c.measurement),
                                               0.5 * (information + information.transpose())));
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

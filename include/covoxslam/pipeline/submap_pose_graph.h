#pragma once
// SubmapPoseGraph: the SLAM system's pose graph in terms of submaps (ids, corrected poses and the
// constraints between them), turned into the backend's 4-DoF graph for each solve. A layer above
// backend::PoseGraph4Dof because submaps loaded from a map file keep their stored poses on one
// shared fixed vertex, absolute positions and heights carry the sensor's lever arm (both:
// SubmapPoseGraph below), and the gauge depends on them: vertex 0 is fixed (voxgraph: the first
// submap) unless horizontal absolute positions on at least two vertices pin the graph, and never
// when submaps were loaded.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/pose_graph_types.h"

namespace covox {
namespace pipeline {

enum class SubmapConstraintKind {
  kOdometry,          // consecutive submaps, from odometry
  kRegistration,      // from aligning a submap's surface to an earlier submap's distance field
  kLoopClosure,       // given from outside (two stamps and a relative transform)
  kAbsolutePosition,  // GNSS position of the sensor
  kHeight,            // height of the sensor
  kGaugeAnchor,       // a near-zero-information link from the loaded map to the first new
                      // submap, so that the new chain has a gauge before anything connects it
};
const char* to_string(SubmapConstraintKind kind);

struct SubmapConstraint {
  SubmapConstraintKind kind = SubmapConstraintKind::kOdometry;
  int64_t from_submap = -1;  // submap ids
  int64_t to_submap = -1;    // -1 for absolute constraints
  // Relative: the pose of `to` in the frame of `from` (dx, dy, dz in `from`, dyaw).
  // Absolute: the sensor position in the world (x, y, z; height: only z is used), yaw unused.
  backend::Pose4Dof measurement;
  // Relative: over (x, y, z, yaw). Absolute position: the upper-left 3x3. Height: (2, 2) only.
  Eigen::Matrix4d information = Eigen::Matrix4d::Zero();
  // Absolute constraints: the sensor's position in the submap frame.
  Eigen::Vector3d lever_arm_m = Eigen::Vector3d::Zero();
  // False: set aside by the consistency gate (registration.gate.max_residual_vox); kept in the
  // graph's list but not given to the solver.
  bool active = true;
  // The solver sees information * weight: the robust loss on registration constraints
  // (pose_graph.registration_loss_scale_sigmas) lowers it for those that disagree with the rest.
  double weight = 1.0;
  // A registration constraint found by place recognition (a loop closure from the submaps'
  // descriptors, pipeline/place_recognition.h) rather than at the estimated overlap.
  bool from_place_recognition = false;

  bool is_absolute() const {
    return kind == SubmapConstraintKind::kAbsolutePosition || kind == SubmapConstraintKind::kHeight;
  }
};

// Factors on the variances of one kind of constraint: x, y, z alike, and yaw.
struct VarianceFactors {
  double translation = 1.0;
  double yaw = 1.0;
};

struct SubmapPoseGraphNode {
  int64_t id = 0;
  backend::Pose4Dof pose;  // corrected T_W_S
  bool loaded = false;     // from a map file: pose fixed
};

// Loaded submaps all share one fixed vertex V (the first loaded submap's), each at its stored
// offset O_a from it, so the solver cannot move them and no stiff "rigid" constraints are needed.
// A relative constraint from a loaded submap a to a submap b with its own vertex becomes exact in
// V: measurement O_a * Z_ab, and since r_a = blockdiag(Rz(yaw(O_a))^T, 1) r_V, information
// R Lambda R^T with R = blockdiag(Rz(yaw(O_a)), 1).
// Absolute positions (GNSS) and heights are measured at the sensor, at lever arm l (its position
// in the submap frame) from the submap origin; the backend's absolute constraint has none, so at
// every solve the measurement moves to the origin with the submap's current yaw:
// p_origin = p_sensor - Rz(yaw) l (height: z - l_z, exact). Repeated solves converge to the
// lever-arm solution as the yaw (set by the far stronger odometry and registrations) settles.
class SubmapPoseGraph {
 public:
  // Appends a submap (ids must increase; loaded submaps only before any other). Throws
  // covox::Error otherwise.
  void add_submap(int64_t id, const backend::Pose4Dof& pose, bool loaded);
  // Throws covox::Error naming the problem when a submap id is unknown or the information is not
  // finite; relative constraints must not end in a loaded submap (they come from new data).
  void add_constraint(const SubmapConstraint& constraint);
  void clear();

  size_t size() const { return nodes_.size(); }
  bool empty() const { return nodes_.empty(); }
  const std::vector<SubmapPoseGraphNode>& nodes() const { return nodes_; }
  const std::vector<SubmapConstraint>& constraints() const { return constraints_; }
  // Index into nodes(), or -1.
  int64_t index_of(int64_t id) const;
  bool contains(int64_t id) const { return index_of(id) >= 0; }
  bool has_loaded_submaps() const { return !nodes_.empty() && nodes_.front().loaded; }
  int64_t last_id() const { return nodes_.empty() ? -1 : nodes_.back().id; }
  int64_t count(SubmapConstraintKind kind) const;
  // The consistency gate's switch for constraint `index` of constraints(); inactive ones are left
  // out of to_backend_graph(). Throws covox::Error for an index out of range.
  void set_active(size_t index, bool active);
  // Throws covox::Error for an unknown index or a weight outside (0, 1].
  void set_weight(size_t index, double weight);
  // The solver sees every odometry (registration) constraint with its translation variances
  // times factors.translation and its yaw variance times factors.yaw: information D^-1/2 I D^-1/2,
  // D = diag(t, t, t, yaw). The noise as estimated from the data (estimate_variance_ratios); all 1
  // at first. Throws covox::Error for another kind or a factor that is not positive and finite.
  void set_variance_factors(SubmapConstraintKind kind, const VarianceFactors& factors);
  VarianceFactors variance_factors(SubmapConstraintKind kind) const;
  // The information the solver sees for `c`, before its weight: scaled by its kind's factors.
  Eigen::Matrix4d scaled_information(const SubmapConstraint& c) const;

  // The backend graph at the current poses, and the mapping back (see apply_solution).
  struct BackendGraph {
    backend::PoseGraph4Dof graph;
    std::vector<int32_t> vertex_of_node;
    std::vector<backend::Pose4Dof> offset_of_node;  // T_vertex_submap
    // For each of graph.constraints, its index in constraints().
    std::vector<size_t> source_of_constraint;
  };
  BackendGraph to_backend_graph() const;
  // Moves every submap to its vertex's solved pose composed with its offset.
  void apply_solution(const BackendGraph& solved);

 private:
  std::vector<SubmapPoseGraphNode> nodes_;
  std::vector<SubmapConstraint> constraints_;
  VarianceFactors odometry_factors_;
  VarianceFactors registration_factors_;
};

// The consistency gate's step (SubmapRegistrationConfig::gate.max_residual_vox, here in metres):
// sets aside the active registration constraints whose measurement lies further than
// `max_residual_m` (horizontal distance in the frame of the `from` submap) from the relative pose
// of their two submaps at the graph's current poses; returns how many. Other kinds are never
// touched. `worst_fraction` > 0 sets aside only those further than max(max_residual_m,
// worst_fraction x the largest residual): the worst first, so that constraints pulled off by them
// are judged again after the next solve (SubmapRegistrationConfig::gate.worst_fraction).
int set_aside_inconsistent_registrations(SubmapPoseGraph* graph, double max_residual_m,
                                         double worst_fraction = 0.0);

// One round of the robust (Cauchy) loss on registration constraints: every active registration
// constraint gets the weight 1 / (1 + r^2 / scale_sigmas^2) at the graph's current poses,
// r^2 = e^T information e (scaled_information; e: the measurement's error in its own convention,
// yaw wrapped).
// Returns the largest change of a weight; solving and reweighting until it is small is
// iteratively reweighted least squares.
double reweight_registrations_cauchy(SubmapPoseGraph* graph, double scale_sigmas);

// Variance-component estimate of the odometry's and the registrations' noise at the graph's
// current poses (a solution): for each kind, as the solver sees it (scaled_information and
// weight), the sum of its squared whitened residual components over the sum of those components'
// redundancies. The redundancy of a component is 1 - (J Sigma J^T)_cc, J its whitened Jacobian
// row and Sigma the solution's covariance (the inverse of the whitened Gauss-Newton matrix of
// every active constraint, gauge vertex held): the part of that residual the other constraints
// can see. A ratio is 1 when the variances fit the residuals; the factors times the ratios are
// the new estimate, and repeating estimate and solve is the fixed point of variance-component
// estimation (Foerstner's). Translation rows (x, y, z) and the yaw row apart; the rows of a
// registration's whitened residual mix its components where its information does, which the
// split ignores. A ratio is 1 where its redundancy sums to under one (too little to judge) or
// the matrix cannot be factorised.
struct VarianceRatios {
  VarianceFactors odometry;
  VarianceFactors registration;
  VarianceFactors odometry_redundancy{0.0, 0.0};
  VarianceFactors registration_redundancy{0.0, 0.0};
};
VarianceRatios estimate_variance_ratios(const SubmapPoseGraph& graph);

// 4-DoF pose algebra (x_a = Rz(yaw) x_b + t): a * b (the inverse is backend::inverse_pose_4dof).
backend::Pose4Dof compose(const backend::Pose4Dof& a, const backend::Pose4Dof& b);

}  // namespace pipeline
}  // namespace covox

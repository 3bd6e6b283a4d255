#pragma once
// Synthetic pose graphs with a known truth, for tests and benchmarks: a drifting submap
// trajectory (a figure-of-eight climbing in z), odometry between consecutive submaps, loop
// closures / registration-like constraints between submaps that are close in space, and (4-DoF)
// optional absolute position and height constraints. Measurements are the truth plus Gaussian
// noise of the stated sigmas; the initial guess is the truth plus an extra random perturbation of
// every vertex (so the solver has work to do), with the fixed vertex exact.
#include <cstdint>

#include "covoxslam/backend/pose_graph.h"

namespace covox {
namespace backend {

struct SyntheticGraphOptions {
  int submaps = 50;
  uint64_t seed = 1;
  double step_m = 2.0;                // distance between consecutive submaps
  double translation_sigma_m = 0.05;  // measurement noise
  double rotation_sigma_rad = 0.01;
  double loop_radius_m = 6.0;    // non-consecutive pairs closer than this get a constraint ...
  int max_loops_per_submap = 4;  // ... at most this many per submap
  double initial_translation_perturbation_m = 0.5;  // initial guess noise (uniform per axis)
  double initial_rotation_perturbation_rad = 0.05;
  int absolute_position_every = 0;  // 4-DoF: a GNSS-like constraint every n submaps (0: none)
  bool height_constraints = false;  // 4-DoF: a height constraint on every submap
};

struct Synthetic4DofGraph {
  PoseGraph4Dof graph;  // initial guess + constraints
  std::vector<Pose4Dof> truth;
};
struct SyntheticSe3Graph {
  Se3PoseGraph graph;
  std::vector<Se3Pose> truth;
};

Synthetic4DofGraph make_synthetic_graph_4dof(const SyntheticGraphOptions& options);
SyntheticSe3Graph make_synthetic_graph_se3(const SyntheticGraphOptions& options);

}  // namespace backend
}  // namespace covox

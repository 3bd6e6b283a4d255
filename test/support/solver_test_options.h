#pragma once
// What the pose-graph solver tests compare with: tight solver options and relative differences.
#include "covoxslam/backend/pose_graph_solver.h"

namespace covox {
namespace testing_support {

// Stopping tolerances of 1e-12 and up to 200 iterations: comparisons (with Ceres, between
// devices) are then about the optimum, not about where a solver stopped. The inner PCG's own
// tolerance and iteration cap are the caller's (a test on long chains needs more iterations).
backend::PoseGraphSolverOptions tight_solver_options(double pcg_relative_tolerance,
                                                     int pcg_max_iterations);

// |a - b| / |b| (b = 0 counts as the smallest positive double).
double relative_difference(double a, double b);

}  // namespace testing_support
}  // namespace covox

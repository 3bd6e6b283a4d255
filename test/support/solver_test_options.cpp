#include "support/solver_test_options.h"

#include <algorithm>
#include <cmath>

namespace covox {
namespace testing_support {

backend::PoseGraphSolverOptions tight_solver_options(double pcg_relative_tolerance,
                                                     int pcg_max_iterations) {
  backend::PoseGraphSolverOptions options;
  options.max_iterations = 200;
  options.function_tolerance = 1e-12;
  options.gradient_tolerance = 1e-12;
  options.parameter_tolerance = 1e-12;
  options.pcg_relative_tolerance = pcg_relative_tolerance;
  options.pcg_max_iterations = pcg_max_iterations;
  return options;
}

double relative_difference(double a, double b) {
  return std::abs(a - b) / std::max(std::abs(b), 1e-300);
}

}  // namespace testing_support
}  // namespace covox

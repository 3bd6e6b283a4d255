#pragma once
// Surface reconstruction quality against a ground-truth mesh (the simulator's world mesh):
//   accuracy     - how far reconstructed vertices lie from the true surface (fraction within each
//                  threshold, mean and median distance): penalises invented or misplaced surface;
//   completeness - the fraction of the true surface area (sampled densely and evenly) that has
//                  reconstructed surface within each threshold: penalises holes.
// Distances farther than the largest threshold are not searched for; they count as "beyond" and
// enter the mean capped at that threshold (stated in the printout), which keeps the search local.
// The ground-truth mesh covers the whole world, including surfaces no flight can see (roofs,
// closed rooms), so completeness is an upper-bounded figure to compare runs, not an absolute one.
#include <cstddef>
#include <iosfwd>
#include <vector>

#include "covoxslam/map/mesh.h"

namespace covox {
namespace eval {

struct ReconstructionEvaluationOptions {
  std::vector<double> thresholds_m = {0.1, 0.2, 0.5};
  // Spacing of the ground-truth surface samples for completeness.
  double sample_spacing_m = 0.1;
};

struct ReconstructionEvaluation {
  std::vector<double> thresholds_m;
  size_t reconstructed_points = 0;
  double truth_area_m2 = 0.0;
  size_t truth_samples = 0;
  // Per threshold: fraction of reconstructed vertices within it of the truth (precision).
  std::vector<double> accuracy_fraction;
  // Per threshold: fraction of the true surface area with reconstruction within it (recall).
  std::vector<double> completeness_fraction;
  // Reconstructed vertex to truth, distances capped at the largest threshold.
  double accuracy_mean_m = 0.0;
  double accuracy_median_m = 0.0;
};

// Throws covox::Error when a threshold or the spacing is not positive or the truth has no
// triangles. A reconstruction without triangles is treated as a point set.
ReconstructionEvaluation evaluate_reconstruction(const map::Mesh& reconstruction,
                                                 const map::Mesh& truth,
                                                 const ReconstructionEvaluationOptions& options);

void print_reconstruction_evaluation(std::ostream& output,
                                     const ReconstructionEvaluation& evaluation);

}  // namespace eval
}  // namespace covox

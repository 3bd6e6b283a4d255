#include "eval/reconstruction_evaluation.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <ostream>

#include <Eigen/Geometry>

#include "covoxslam/core/error.h"
#include "eval/mesh_distance.h"

namespace covox {
namespace eval {
namespace {

Eigen::Vector3d to_eigen(const Vec3f& v) { return Eigen::Vector3d(v.x, v.y, v.z); }

}  // namespace

ReconstructionEvaluation evaluate_reconstruction(const map::Mesh& reconstruction,
                                                 const map::Mesh& truth,
                                                 const ReconstructionEvaluationOptions& options) {
  if (options.thresholds_m.empty()) throw Error("reconstruction evaluation: no thresholds given");
  for (double t : options.thresholds_m) {
    if (!(t > 0.0)) throw Error("reconstruction evaluation: thresholds must be positive");
  }
  if (!(options.sample_spacing_m > 0.0)) {
    throw Error("reconstruction evaluation: sample spacing must be positive");
  }
  if (truth.triangles.empty())
    throw Error("reconstruction evaluation: the ground-truth mesh has no triangles");
  ReconstructionEvaluation result;
  result.thresholds_m = options.thresholds_m;
  const double radius = *std::max_element(options.thresholds_m.begin(), options.thresholds_m.end());
  const size_t levels = options.thresholds_m.size();

  // Accuracy: every reconstructed vertex against the true triangles. Cells of the search radius
  // keep each query to the 27 cells around it; nothing beyond the radius is searched for.
  const MeshDistance truth_distance(truth, radius);
  std::vector<double> distances(reconstruction.vertices_m.size());
  for (size_t i = 0; i < distances.size(); ++i) {
    distances[i] = truth_distance.distance_m(to_eigen(reconstruction.vertices_m[i]), radius);
  }
  result.reconstructed_points = distances.size();
  result.accuracy_fraction.assign(levels, 0.0);
  double sum = 0.0;
  for (double& d : distances) {
    for (size_t k = 0; k < levels; ++k) {
      if (d <= options.thresholds_m[k]) result.accuracy_fraction[k] += 1.0;
    }
    d = std::min(
        d, radius);  // "beyond the search" (infinity) enters the mean and median as the radius
    sum += d;
  }
  if (!distances.empty()) {
    for (double& f : result.accuracy_fraction) f /= static_cast<double>(distances.size());
    result.accuracy_mean_m = sum / static_cast<double>(distances.size());
    std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
    result.accuracy_median_m = distances[distances.size() / 2];
  }

  // Completeness: each true triangle is cut into k^2 equal sub-triangles (k from the spacing);
  // their centroids are the samples, each standing for area / k^2.
  // A reconstruction without triangles is measured as the point set of its vertices.
  const MeshDistance reconstruction_distance(reconstruction, radius);
  std::vector<double> covered_area(levels, 0.0);
  for (size_t t = 0; t < truth.triangle_count(); ++t) {
    const Eigen::Vector3d a = to_eigen(truth.vertices_m[truth.triangles[3 * t]]);
    const Eigen::Vector3d b = to_eigen(truth.vertices_m[truth.triangles[3 * t + 1]]);
    const Eigen::Vector3d c = to_eigen(truth.vertices_m[truth.triangles[3 * t + 2]]);
    const double area = 0.5 * (b - a).cross(c - a).norm();
    if (!(area > 0.0)) continue;
    const double longest = std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()});
    const int k = std::max(1, static_cast<int>(std::ceil(longest / options.sample_spacing_m)));
    const double sample_area = area / (static_cast<double>(k) * k);
    result.truth_area_m2 += area;
    const auto sample = [&](double u, double v) {
      const Eigen::Vector3d p = a + u * (b - a) + v * (c - a);
      const double d = reconstruction_distance.distance_m(p, radius);
      ++result.truth_samples;
      for (size_t level = 0; level < levels; ++level) {
        if (d <= options.thresholds_m[level]) covered_area[level] += sample_area;
      }
    };
    for (int i = 0; i < k; ++i) {
      for (int j = 0; i + j < k; ++j) {
        sample((i + 1.0 / 3.0) / k, (j + 1.0 / 3.0) / k);  // upright sub-triangle
        if (i + j < k - 1) sample((i + 2.0 / 3.0) / k, (j + 2.0 / 3.0) / k);  // inverted one
      }
    }
  }
  result.completeness_fraction.resize(levels);
  for (size_t level = 0; level < levels; ++level) {
    result.completeness_fraction[level] = covered_area[level] / result.truth_area_m2;
  }
  return result;
}

void print_reconstruction_evaluation(std::ostream& output,
                                     const ReconstructionEvaluation& evaluation) {
  const double cap =
      *std::max_element(evaluation.thresholds_m.begin(), evaluation.thresholds_m.end());
  output << "reconstruction: " << evaluation.reconstructed_points << " vertices; truth "
         << std::fixed << std::setprecision(1) << evaluation.truth_area_m2 << " m^2 in "
         << evaluation.truth_samples << " samples\n";
  output << std::setprecision(4) << "accuracy: mean " << evaluation.accuracy_mean_m << " m, median "
         << evaluation.accuracy_median_m << " m (distances capped at " << cap << " m)\n";
  output << std::setw(14) << "threshold m" << std::setw(12) << "accuracy" << std::setw(14)
         << "completeness"
         << "\n";
  for (size_t k = 0; k < evaluation.thresholds_m.size(); ++k) {
    output << std::setw(14) << evaluation.thresholds_m[k] << std::setw(11)
           << 100.0 * evaluation.accuracy_fraction[k] << "%" << std::setw(13)
           << 100.0 * evaluation.completeness_fraction[k] << "%\n";
  }
}

}  // namespace eval
}  // namespace covox

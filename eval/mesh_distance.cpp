#include "eval/mesh_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "covoxslam/core/error.h"

namespace covox {
namespace eval {
namespace {

// More shells than this means a query could visit billions of empty cells: the cell size does
// not suit the search radius, which is a caller's mistake better reported than waited out.
constexpr double kMaxShells = 1024.0;

Eigen::Vector3d to_eigen(const Vec3f& v) { return Eigen::Vector3d(v.x, v.y, v.z); }

}  // namespace

Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;  // vertex region of a
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;  // vertex region of b
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + (d1 / (d1 - d3)) * ab;  // edge ab
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;  // vertex region of c
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + (d2 / (d2 - d6)) * ac;  // edge ac
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {  // edge bc
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  }
  // Face region: barycentric coordinates. Collinear corners make the denominator vanish; the
  // tests above have then already caught every point except ones for which a is as good as any.
  const double denominator = va + vb + vc;
  if (!(std::abs(denominator) > 0.0)) return a;
  return a + ab * (vb / denominator) + ac * (vc / denominator);
}

MeshDistance::MeshDistance(const map::Mesh& mesh, double cell_size_m) : cell_m_(cell_size_m) {
  if (!(cell_size_m > 0.0) || !std::isfinite(cell_size_m)) {
    throw Error("mesh distance: the cell size must be positive and finite, got " +
                std::to_string(cell_size_m));
  }
  const bool point_set = mesh.triangles.empty();
  const size_t count = point_set ? mesh.vertices_m.size() : mesh.triangle_count();
  triangles_.reserve(count);
  for (size_t t = 0; t < count; ++t) {
    if (point_set) {
      const Eigen::Vector3d v = to_eigen(mesh.vertices_m[t]);
      triangles_.push_back({v, v, v});  // a degenerate triangle is its one point
    } else {
      for (size_t k = 0; k < 3; ++k) {
        if (mesh.triangles[3 * t + k] >= mesh.vertices_m.size()) {
          throw Error("mesh distance: triangle " + std::to_string(t) + " refers to vertex " +
                      std::to_string(mesh.triangles[3 * t + k]) + " of " +
                      std::to_string(mesh.vertices_m.size()));
        }
      }
      triangles_.push_back({to_eigen(mesh.vertices_m[mesh.triangles[3 * t]]),
                            to_eigen(mesh.vertices_m[mesh.triangles[3 * t + 1]]),
                            to_eigen(mesh.vertices_m[mesh.triangles[3 * t + 2]])});
    }
  }

  // A triangle goes into every cell of its bounding box that it may intersect: those whose
  // centre lies within half a cell diagonal of it. Listing only the bounding box would be correct
  // too, but a long diagonal triangle would then crowd many cells it never touches. The small
  // slack keeps rounding from dropping a cell the triangle just grazes, since a missing entry
  // would make a distance wrong while an extra one only costs a test.
  const double half_diagonal_m = 0.5 * std::sqrt(3.0) * cell_m_ * (1.0 + 1e-9);
  for (size_t t = 0; t < triangles_.size(); ++t) {
    const Triangle& triangle = triangles_[t];
    const Eigen::Array3i low = cell_of(triangle.a.cwiseMin(triangle.b).cwiseMin(triangle.c));
    const Eigen::Array3i high = cell_of(triangle.a.cwiseMax(triangle.b).cwiseMax(triangle.c));
    for (int z = low.z(); z <= high.z(); ++z) {
      for (int y = low.y(); y <= high.y(); ++y) {
        for (int x = low.x(); x <= high.x(); ++x) {
          const Eigen::Vector3d centre =
              (Eigen::Vector3d(x, y, z) + Eigen::Vector3d::Constant(0.5)) * cell_m_;
          const Eigen::Vector3d closest =
              closest_point_on_triangle(centre, triangle.a, triangle.b, triangle.c);
          if ((closest - centre).norm() <= half_diagonal_m)
            cells_[key(x, y, z)].push_back(static_cast<uint32_t>(t));
        }
      }
    }
  }
}

double MeshDistance::distance_m(const Eigen::Vector3d& p, double max_distance_m) const {
  if (!(max_distance_m >= 0.0) || !std::isfinite(max_distance_m)) {
    throw Error("mesh distance: the search radius must be finite and not negative, got " +
                std::to_string(max_distance_m));
  }
  if (!p.allFinite()) throw Error("mesh distance: the query point is not finite");
  const double shells = std::ceil(max_distance_m / cell_m_);
  if (shells > kMaxShells) {
    throw Error("mesh distance: a search radius of " + std::to_string(max_distance_m) + " m is " +
                std::to_string(shells) + " cells of " + std::to_string(cell_m_) +
                " m; use a larger cell size or a smaller radius");
  }
  const int last_shell = static_cast<int>(shells);
  const Eigen::Array3i home = cell_of(p);
  double best_m = std::numeric_limits<double>::infinity();
  const auto visit = [&](int x, int y, int z) {
    const auto cell = cells_.find(key(home.x() + x, home.y() + y, home.z() + z));
    if (cell == cells_.end()) return;
    for (uint32_t t : cell->second) {
      const Triangle& triangle = triangles_[t];
      best_m = std::min(
          best_m, (closest_point_on_triangle(p, triangle.a, triangle.b, triangle.c) - p).norm());
    }
  };
  for (int shell = 0; shell <= last_shell; ++shell) {
    // The cells at Chebyshev distance `shell` from home: whole rows on the shell's top, bottom,
    // front and back faces, only the two end cells of each row in between.
    for (int z = -shell; z <= shell; ++z) {
      for (int y = -shell; y <= shell; ++y) {
        if (std::abs(z) == shell || std::abs(y) == shell) {
          for (int x = -shell; x <= shell; ++x) visit(x, y, z);
        } else {
          visit(-shell, y, z);
          if (shell > 0) visit(shell, y, z);
        }
      }
    }
    // A point at distance d from p lies at most ceil(d / cell) cells away along each axis, so
    // every element within shell cells' length of p has now been met: a nearer one cannot wait
    // in an unvisited shell.
    if (best_m <= shell * cell_m_) break;
  }
  return best_m <= max_distance_m ? best_m : std::numeric_limits<double>::infinity();
}

Eigen::Array3i MeshDistance::cell_of(const Eigen::Vector3d& p) const {
  return (p / cell_m_).array().floor().cast<int>();
}

// 21 bits per axis. Cells a multiple of 2^21 apart share a key; that only puts extra candidates
// in a list (each is measured exactly), never hides one, so distances stay exact.
int64_t MeshDistance::key(int x, int y, int z) {
  return (int64_t(x) & 0x1fffff) | (int64_t(y) & 0x1fffff) << 21 | (int64_t(z) & 0x1fffff) << 42;
}

}  // namespace eval
}  // namespace covox

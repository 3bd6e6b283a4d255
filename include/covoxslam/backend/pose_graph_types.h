#pragma once
// The poses and constraints of the pose graph, as the kernels see them (trivially copyable, so
// they live in Buffer<T> on either device).
//
// Two modes share one solver:
//  * SE(3): 6-DoF poses (g2o data, general use). Tangent order (dtx, dty, dtz, dthx, dthy, dthz).
//  * 4-DoF: gravity-aligned submap poses (x, y, z, yaw), as in voxgraph.
// Every constraint stores the square root S of its information matrix (S^T S = information), so
// its whitened residual is f = S r and its cost 0.5 |f|^2 (Ceres' convention).
#include <cstdint>

namespace covox {
namespace backend {

// Rotation as a unit quaternion (x, y, z, w) and a translation: the map x_W = R x_S + t.
struct Se3Pose {
  double rotation[4] = {0.0, 0.0, 0.0, 1.0};
  double translation[3] = {0.0, 0.0, 0.0};
};

// Position and heading about the gravity axis z: x_W = Rz(yaw) x_S + (x, y, z).
struct Pose4Dof {
  double x = 0.0, y = 0.0, z = 0.0, yaw = 0.0;
};

// Vertex indices are positions in the graph's pose array (not file ids).
constexpr int32_t kNoVertex = -1;

struct Se3Constraint {
  int32_t from = 0;                  // i
  int32_t to = 0;                    // j
  Se3Pose measurement;               // Z_ij, the measured T_i^-1 T_j
  double sqrt_information[36] = {};  // 6x6 row-major
};

enum class Constraint4DofKind : int32_t {
  kRelativePose = 0,      // odometry or loop closure between `from` and `to`
  kAbsolutePosition = 1,  // GNSS-like position of `from` (a height constraint is the z-only case)
};

struct Constraint4Dof {
  int32_t from = 0;
  int32_t to = kNoVertex;  // kNoVertex for absolute constraints
  Constraint4DofKind kind = Constraint4DofKind::kRelativePose;
  // Relative: (dx, dy, dz) in the frame of `from` and dyaw. Absolute: the position, yaw unused.
  Pose4Dof measurement;
  double sqrt_information[16] = {};  // 4x4 row-major; absolute: only the upper-left 3x3 is used
};

}  // namespace backend
}  // namespace covox

#pragma once
// Device-side pieces of registration (registration.h) and the backend-templated steps, defined in
// registration_impl.h and instantiated once per backend.
#include <cmath>
#include <cstdint>

#include "covoxslam/backend/registration.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/integrators/esdf_lookup.h"

namespace covox {
namespace backend {

// Distance field of submap j as the residual sees it: ESDF corners through EsdfLookup, replaced by
// TSDF corners near the surface when tsdf_band_m > 0 (see registration.h for why).
struct RegistrationDistanceLookup {
  integrators::EsdfLookup esdf;
  VoxelView<map::TsdfVoxel, Layout::kSoA> tsdf;
  float tsdf_band_m = 0.0f;  // 0: ESDF only (voxgraph)
  float min_tsdf_weight = 1e-4f;
  int32_t stride_vox = 1;  // corners every this many voxels (coarse levels: ESDF only, band 0)

  COVOX_HD_INLINE bool corner(const Index3D& v, double* distance_m) const {
    if (tsdf_band_m > 0.0f) {
      const int64_t index = esdf.indexer.pool_index(v);
      if (index < 0) return false;
      const map::TsdfVoxel voxel = tsdf.load(index);
      if (voxel.weight >= min_tsdf_weight && fabsf(voxel.distance_m) < tsdf_band_m) {
        *distance_m = voxel.distance_m;
        return true;
      }
    }
    float d = 0.0f;
    if (!esdf.voxel(v, &d)) return false;
    *distance_m = d;
    return true;
  }

  // Trilinear distance and gradient (d distance / d q, frame j). Interpolated in double, unlike
  // EsdfLookup::sample, so that central differences in the Jacobian test are not float noise.
  COVOX_HD_INLINE bool sample(double qx, double qy, double qz, double* distance_m,
                              double* gradient) const {
    // The corners are voxel centres (k + 0.5) voxel with k a multiple of the stride, so a cell
    // spans stride voxels and the gradient divides by its size.
    const double stride = static_cast<double>(stride_vox);
    const double voxel = esdf.voxel_size * stride;
    const double gx = (qx / esdf.voxel_size - 0.5) / stride,
                 gy = (qy / esdf.voxel_size - 0.5) / stride,
                 gz = (qz / esdf.voxel_size - 0.5) / stride;
    const double bx = floor(gx), by = floor(gy), bz = floor(gz);
    // Beyond the voxel index range int32 would wrap onto other voxels: treat as unobserved.
    if (!(fabs(bx) < 1e9 / stride && fabs(by) < 1e9 / stride && fabs(bz) < 1e9 / stride))
      return false;
    const Index3D base(static_cast<int32_t>(bx), static_cast<int32_t>(by),
                       static_cast<int32_t>(bz));
    const double fx = gx - bx, fy = gy - by, fz = gz - bz;
    double d[8];
    for (int c = 0; c < 8; ++c) {
      const Index3D cell = base + Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1);
      if (!corner(Index3D(cell.x * stride_vox, cell.y * stride_vox, cell.z * stride_vox), &d[c]))
        return false;
    }
    const double x00 = d[0] + fx * (d[1] - d[0]), x10 = d[2] + fx * (d[3] - d[2]);
    const double x01 = d[4] + fx * (d[5] - d[4]), x11 = d[6] + fx * (d[7] - d[6]);
    const double y0 = x00 + fy * (x10 - x00), y1 = x01 + fy * (x11 - x01);
    *distance_m = y0 + fz * (y1 - y0);
    gradient[0] = ((1 - fz) * ((1 - fy) * (d[1] - d[0]) + fy * (d[3] - d[2])) +
                   fz * ((1 - fy) * (d[5] - d[4]) + fy * (d[7] - d[6]))) /
                  voxel;
    gradient[1] = ((1 - fz) * (x10 - x00) + fz * (x11 - x01)) / voxel;
    gradient[2] = (y1 - y0) / voxel;
    return true;
  }
};

// The pair's geometry, composed on the host in double: q = R_ji p + t_ji with
// R_ji = Rz(yaw_i - yaw_j), t_ji = Rz(yaw_j)^T (t_i - t_j); Rz(yaw_j) turns frame-j gradients
// into world directions for the translation Jacobians.
struct RegistrationPairGeometry {
  double cos_ji = 1.0, sin_ji = 0.0;
  double t_ji[3] = {0.0, 0.0, 0.0};
  double cos_j = 1.0, sin_j = 0.0;
};

// Composes the pair's geometry from the two world poses (in double; device code too, so that the
// pose graph can recompute it for every pair at every LM iterate).
COVOX_HD_INLINE RegistrationPairGeometry registration_pair_geometry(const Pose4Dof& T_W_Si,
                                                                    const Pose4Dof& T_W_Sj) {
  RegistrationPairGeometry pair;
  pair.cos_ji = cos(T_W_Si.yaw - T_W_Sj.yaw);
  pair.sin_ji = sin(T_W_Si.yaw - T_W_Sj.yaw);
  pair.cos_j = cos(T_W_Sj.yaw);
  pair.sin_j = sin(T_W_Sj.yaw);
  const double dx = T_W_Si.x - T_W_Sj.x, dy = T_W_Si.y - T_W_Sj.y;
  pair.t_ji[0] = pair.cos_j * dx + pair.sin_j * dy;
  pair.t_ji[1] = -pair.sin_j * dx + pair.cos_j * dy;
  pair.t_ji[2] = T_W_Si.z - T_W_Sj.z;
  return pair;
}

struct RobustLossParams {
  RobustLoss loss = RobustLoss::kNone;
  double scale = 1.0;

  // rho(s) and rho'(s) for s = r^2.
  COVOX_HD_INLINE void evaluate(double s, double* rho, double* rho_prime) const {
    const double a2 = scale * scale;
    switch (loss) {
      case RobustLoss::kHuber:
        if (s <= a2) {
          *rho = s;
          *rho_prime = 1.0;
        } else {
          const double root = sqrt(s);
          *rho = 2.0 * scale * root - a2;
          *rho_prime = scale / root;
        }
        return;
      case RobustLoss::kCauchy:
        *rho = a2 * log1p(s / a2);
        *rho_prime = 1.0 / (1.0 + s / a2);
        return;
      case RobustLoss::kNone:
      default:
        *rho = s;
        *rho_prime = 1.0;
        return;
    }
  }
};

// One point's residual, Jacobians and robust weight.
COVOX_HD_INLINE RegistrationResidual registration_residual(const RegistrationPoint& point,
                                                           const RegistrationDistanceLookup& lookup,
                                                           const RegistrationPairGeometry& pair,
                                                           const RobustLossParams& robust,
                                                           bool tsdf_target) {
  RegistrationResidual out;
  const double px = point.position_m.x, py = point.position_m.y, pz = point.position_m.z;
  // R_ji p, then q in frame j.
  const double rx = pair.cos_ji * px - pair.sin_ji * py;
  const double ry = pair.sin_ji * px + pair.cos_ji * py;
  const double qx = rx + pair.t_ji[0], qy = ry + pair.t_ji[1], qz = pz + pair.t_ji[2];
  double distance = 0.0, g[3];
  if (!lookup.sample(qx, qy, qz, &distance, g)) return out;
  const double sqrt_weight = sqrt(static_cast<double>(point.weight));
  const double target = tsdf_target ? static_cast<double>(point.tsdf_distance_m) : 0.0;
  out.residual = sqrt_weight * (distance - target);
  // d q / d t_i = Rz_j^T, so d r / d t_i = Rz_j g (and the negative for t_j).
  const double wx = pair.cos_j * g[0] - pair.sin_j * g[1];
  const double wy = pair.sin_j * g[0] + pair.cos_j * g[1];
  const double wz = g[2];
  // d q / d yaw_i = e_z x (R_ji p) (Rz commutes with e_z x); d q / d yaw_j = -e_z x q.
  const double dyaw_i = g[0] * (-ry) + g[1] * rx;
  const double dyaw_j = -(g[0] * (-qy) + g[1] * qx);
  out.jacobian_i[0] = sqrt_weight * wx;
  out.jacobian_i[1] = sqrt_weight * wy;
  out.jacobian_i[2] = sqrt_weight * wz;
  out.jacobian_i[3] = sqrt_weight * dyaw_i;
  out.jacobian_j[0] = -sqrt_weight * wx;
  out.jacobian_j[1] = -sqrt_weight * wy;
  out.jacobian_j[2] = -sqrt_weight * wz;
  out.jacobian_j[3] = sqrt_weight * dyaw_j;
  double rho = 0.0, rho_prime = 0.0;
  robust.evaluate(out.residual * out.residual, &rho, &rho_prime);
  out.cost = 0.5 * rho;
  out.robust_weight = rho_prime;
  out.valid = 1;
  return out;
}

// The reduced sums over points (upper triangle of the 4x4 pose-i block, row-major).
struct RegistrationSums {
  double hessian[10] = {};
  double gradient[4] = {};
  double cost = 0.0;
  int64_t used = 0;
};

struct RegistrationSumsOfResidual {
  COVOX_HD_INLINE RegistrationSums operator()(const RegistrationResidual& r) const {
    RegistrationSums s;
    if (!r.valid) return s;
    int k = 0;
    for (int row = 0; row < 4; ++row) {
      for (int col = row; col < 4; ++col)
        s.hessian[k++] = r.robust_weight * r.jacobian_i[row] * r.jacobian_i[col];
      s.gradient[row] = r.robust_weight * r.jacobian_i[row] * r.residual;
    }
    s.cost = r.cost;
    s.used = 1;
    return s;
  }
};

struct AddRegistrationSums {
  COVOX_HD_INLINE RegistrationSums operator()(const RegistrationSums& a,
                                              const RegistrationSums& b) const {
    RegistrationSums s;
    for (int k = 0; k < 10; ++k) s.hessian[k] = a.hessian[k] + b.hessian[k];
    for (int k = 0; k < 4; ++k) s.gradient[k] = a.gradient[k] + b.gradient[k];
    s.cost = a.cost + b.cost;
    s.used = a.used + b.used;
    return s;
  }
};

// Host helpers shared by the pairwise aligner and the pose graph's registration terms
// (registration.cpp). Throws covox::Error on a bad configuration.
void validate_registration_residual_config(const RegistrationResidualConfig& config);
// The lookup of map_j's field for kernels on map_j's device (tsdf_band_m from `config`).
RegistrationDistanceLookup make_registration_lookup(const map::TsdfMap& map_j,
                                                    const RegistrationResidualConfig& config);
// Normal equations from reduced sums: the upper triangle of the 4x4 Hessian (row-major), the
// gradient, the cost, the points used and the points evaluated.
RegistrationNormalEquations normal_equations_from_sums(const double* upper_hessian,
                                                       const double* gradient, double cost,
                                                       int64_t used_points, int64_t points);
// Both sums added (used and skipped points counted over both).
RegistrationNormalEquations sum_of(const RegistrationNormalEquations& a,
                                   const RegistrationNormalEquations& b);

// A deterministic uniform number in [0, 1) per voxel (and seed): the sampling decision.
COVOX_HD_INLINE double registration_sample_uniform(int32_t x, int32_t y, int32_t z, uint32_t seed) {
  uint64_t h = (static_cast<uint64_t>(static_cast<uint32_t>(x)) * 0x9E3779B97F4A7C15ull) ^
               (static_cast<uint64_t>(static_cast<uint32_t>(y)) * 0xC2B2AE3D27D4EB4Full) ^
               (static_cast<uint64_t>(static_cast<uint32_t>(z)) * 0x165667B19E3779F9ull) ^
               (static_cast<uint64_t>(seed) << 17);
  // splitmix64 finaliser: mixes every input bit into the top 53.
  h ^= h >> 30;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 27;
  h *= 0x94D049BB133111EBull;
  h ^= h >> 31;
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

// Surface voxels of the blocks (given in a fixed order) compacted into `points`; returns the
// number of surface voxels before sampling.
template <class Backend>
int64_t registration_collect_points(Backend backend, VoxelView<map::TsdfVoxel, Layout::kSoA> tsdf,
                                    const Index3D* block_indices, const uint32_t* block_slots,
                                    int64_t block_count, int32_t side, float voxel_size_m,
                                    const RegistrationPointsConfig& config,
                                    Buffer<RegistrationPoint>* points, const Stream& stream);

template <class Backend>
void registration_evaluate(Backend backend, const RegistrationPoint* points, int64_t count,
                           RegistrationDistanceLookup lookup, RegistrationPairGeometry pair,
                           RobustLossParams robust, bool tsdf_target, RegistrationResidual* out,
                           const Stream& stream);

template <class Backend>
RegistrationSums registration_reduce(Backend backend, const RegistrationResidual* residuals,
                                     int64_t count, const Stream& stream);

}  // namespace backend
}  // namespace covox

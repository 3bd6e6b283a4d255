#pragma once
// The data-parallel steps of the pose graph's registration terms (registration_terms.h), written
// once for both backends and included by the solver's instantiation files through
// registration_terms_workspace.h.
//
// Layout: the points of all terms are concatenated term by term; `point_term[p]` names a point's
// term. Every term's points are cut into chunks of at most kRegistrationChunkPoints that never
// cross a term, so the per-term sums are a fixed two-level reduction (points in a chunk in order,
// then chunks of a term in order): deterministic and the same order on both backends, no atomics.
#include <cstdint>

#include "covoxslam/backend/internal/registration_ops.h"
#include "covoxslam/core/parallel.h"

namespace covox {
namespace backend {

constexpr int64_t kRegistrationChunkPoints = 64;

// A term as the kernels see it.
struct RegistrationTermView {
  int32_t vertex_i = 0;
  int32_t vertex_j = 0;
  int32_t field = 0;  // index into the array of field lookups (one per distinct map)
  uint8_t tsdf_target = 0;
  float tsdf_band_m = 0.0f;  // 0: ESDF only
  float min_tsdf_weight = 1e-4f;
  double inverse_sigma = 1.0;  // 1 / RegistrationTerm::residual_sigma
  RobustLossParams robust;
};

// One point's contribution before the reduction: the residual, its Jacobians (sqrt(w) applied,
// not the robust weight), the IRLS weight rho'(r^2), and whether it fell inside j's field.
struct RegistrationPointTerm {
  double residual = 0.0;
  double jacobian_i[4] = {};
  double jacobian_j[4] = {};
  double robust_weight = 0.0;
  double valid = 0.0;  // 1 or 0, a double so that the reduction sums it with the rest
};

// Per term (and per chunk) sums, kRegistrationSumStride doubles:
//   [0, 16) H_ii, [16, 32) H_ij (rows: i, columns: j), [32, 48) H_jj   (4x4 row-major, full)
//   [48, 52) g_i, [52, 56) g_j, [56] points used.
// The normal-equation assembly reads the same layout (normal_equations_impl.h).
constexpr int kRegistrationSumStride = 57;
constexpr int kRegistrationHiiOffset = 0;
constexpr int kRegistrationHijOffset = 16;
constexpr int kRegistrationHjjOffset = 32;
constexpr int kRegistrationGiOffset = 48;
constexpr int kRegistrationGjOffset = 52;
constexpr int kRegistrationUsedOffset = 56;

// The geometry of every term at `poses`.
template <class Backend>
void registration_terms_geometry(Backend backend, const Stream& stream,
                                 const RegistrationTermView* terms, int64_t term_count,
                                 const Pose4Dof* poses, RegistrationPairGeometry* geometry) {
  parallel_for(backend, stream, term_count, [=] COVOX_HD(int64_t t) {
    geometry[t] = registration_pair_geometry(poses[terms[t].vertex_i], poses[terms[t].vertex_j]);
  });
}

// One point's residual scaled by 1 / sigma, then its robust loss (the term's residual; also what
// the Ceres oracle evaluates).
COVOX_HD_INLINE RegistrationResidual registration_scaled_residual(
    const RegistrationPoint& point, const RegistrationDistanceLookup& lookup,
    const RegistrationPairGeometry& geometry, const RobustLossParams& robust, bool tsdf_target,
    double inverse_sigma) {
  RegistrationResidual r =
      registration_residual(point, lookup, geometry, RobustLossParams{}, tsdf_target);
  if (!r.valid) return r;
  r.residual *= inverse_sigma;
  for (int k = 0; k < 4; ++k) {
    r.jacobian_i[k] *= inverse_sigma;
    r.jacobian_j[k] *= inverse_sigma;
  }
  double rho = 0.0, rho_prime = 0.0;
  robust.evaluate(r.residual * r.residual, &rho, &rho_prime);
  r.cost = 0.5 * rho;
  r.robust_weight = rho_prime;
  return r;
}

COVOX_HD_INLINE RegistrationResidual registration_term_residual(
    const RegistrationPoint& point, const RegistrationTermView& term,
    const RegistrationDistanceLookup* fields, const RegistrationPairGeometry& geometry) {
  RegistrationDistanceLookup lookup = fields[term.field];
  lookup.tsdf_band_m = term.tsdf_band_m;
  lookup.min_tsdf_weight = term.min_tsdf_weight;
  return registration_scaled_residual(point, lookup, geometry, term.robust, term.tsdf_target != 0,
                                      term.inverse_sigma);
}

// Every point of every term in one launch: its residual, Jacobians and cost (0 when invalid).
// `out` may be null (trial steps need only the costs).
template <class Backend>
void registration_terms_evaluate(Backend backend, const Stream& stream,
                                 const RegistrationPoint* points, const int32_t* point_term,
                                 int64_t point_count, const RegistrationTermView* terms,
                                 const RegistrationDistanceLookup* fields,
                                 const RegistrationPairGeometry* geometry,
                                 RegistrationPointTerm* out, double* costs) {
  parallel_for(backend, stream, point_count, [=] COVOX_HD(int64_t p) {
    const int32_t t = point_term[p];
    const RegistrationResidual r =
        registration_term_residual(points[p], terms[t], fields, geometry[t]);
    costs[p] = r.valid ? r.cost : 0.0;
    if (out == nullptr) return;
    RegistrationPointTerm o;
    if (r.valid) {
      o.residual = r.residual;
      for (int k = 0; k < 4; ++k) {
        o.jacobian_i[k] = r.jacobian_i[k];
        o.jacobian_j[k] = r.jacobian_j[k];
      }
      o.robust_weight = r.robust_weight;
      o.valid = 1.0;
    }
    out[p] = o;
  });
}

// Level 1: one thread per (chunk, group) sums its chunk's points in order. Groups split the 57
// sums so that a thread keeps at most 16 accumulators: 0 H_ii, 1 H_ij, 2 H_jj, 3 g_i, g_j, used.
template <class Backend>
void registration_terms_reduce_chunks(Backend backend, const Stream& stream,
                                      const RegistrationPointTerm* point_terms,
                                      const int64_t* chunk_offsets, int64_t chunk_count,
                                      double* chunk_sums) {
  parallel_for(backend, stream, chunk_count * 4, [=] COVOX_HD(int64_t task) {
    const int64_t chunk = task / 4;
    const int group = static_cast<int>(task % 4);
    double sum[16];
    for (int k = 0; k < 16; ++k) sum[k] = 0.0;
    for (int64_t p = chunk_offsets[chunk]; p < chunk_offsets[chunk + 1]; ++p) {
      const RegistrationPointTerm& e = point_terms[p];
      const double w = e.robust_weight;
      if (group == 3) {
        for (int r = 0; r < 4; ++r) {
          sum[r] += w * e.jacobian_i[r] * e.residual;
          sum[4 + r] += w * e.jacobian_j[r] * e.residual;
        }
        sum[8] += e.valid;
      } else {
        const double* a = group == 2 ? e.jacobian_j : e.jacobian_i;
        const double* b = group == 0 ? e.jacobian_i : e.jacobian_j;
        for (int r = 0; r < 4; ++r) {
          const double wa = w * a[r];
          for (int c = 0; c < 4; ++c) sum[r * 4 + c] += wa * b[c];
        }
      }
    }
    double* out = chunk_sums + chunk * kRegistrationSumStride;
    if (group == 3) {
      for (int k = 0; k < 9; ++k) out[kRegistrationGiOffset + k] = sum[k];
    } else {
      for (int k = 0; k < 16; ++k) out[group * 16 + k] = sum[k];
    }
  });
}

// Level 2: one thread per (term, entry) sums the term's chunks in order.
template <class Backend>
void registration_terms_reduce_terms(Backend backend, const Stream& stream,
                                     const double* chunk_sums, const int64_t* term_chunk_offsets,
                                     int64_t term_count, double* term_sums) {
  parallel_for(backend, stream, term_count * kRegistrationSumStride, [=] COVOX_HD(int64_t task) {
    const int64_t term = task / kRegistrationSumStride;
    const int entry = static_cast<int>(task % kRegistrationSumStride);
    double sum = 0.0;
    for (int64_t c = term_chunk_offsets[term]; c < term_chunk_offsets[term + 1]; ++c) {
      sum += chunk_sums[c * kRegistrationSumStride + entry];
    }
    term_sums[task] = sum;
  });
}

}  // namespace backend
}  // namespace covox

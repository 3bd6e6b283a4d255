#pragma once
// The data-parallel steps of the pose-graph solver, written once for both backends (included only
// by the instantiation files through pose_graph_solver_impl.h). All pointers are memory of the
// backend's device; matrices are D x D row-major, one after the other.
#include <thrust/functional.h>

#include "covoxslam/backend/internal/registration_terms_ops.h"
#include "covoxslam/core/parallel.h"

namespace covox {
namespace backend {

// Residuals f, Jacobians and the cost 0.5 |f|^2 of every constraint.
template <class Model, class Backend>
void evaluate_constraints(Backend backend, const Stream& stream,
                          const typename Model::Constraint* constraints, int64_t count,
                          const typename Model::Pose* poses, double* residuals, double* jac_from,
                          double* jac_to, double* costs) {
  constexpr int D = Model::kDim;
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t k) {
    double* f = residuals + k * D;
    Model::evaluate(constraints[k], poses, f, jac_from + k * D * D, jac_to + k * D * D);
    double sum = 0.0;
    for (int r = 0; r < D; ++r) sum += f[r] * f[r];
    costs[k] = 0.5 * sum;
  });
}

// The cost of every constraint only (trial steps that may be rejected need no Jacobians).
template <class Model, class Backend>
void constraint_costs(Backend backend, const Stream& stream,
                      const typename Model::Constraint* constraints, int64_t count,
                      const typename Model::Pose* poses, double* costs) {
  parallel_for(backend, stream, count,
               [=] COVOX_HD(int64_t k) { costs[k] = Model::cost(constraints[k], poses); });
}

// The device copies of BlockSparseStructure's arrays.
struct StructureView {
  int32_t vertex_count;
  int32_t fixed_vertex;
  int64_t off_block_count;
  const int32_t* diag_offsets;
  const int32_t* diag_terms;
  const int32_t* off_offsets;
  const int32_t* off_terms;
  const int32_t* row_offsets;
  const int32_t* row_entries;
  const int32_t* row_columns;
  // Terms k >= constraint_count are registration terms (registration_terms.h): their blocks are
  // read from term_sums (kRegistrationSumStride doubles per term, side 0 = vertex i, side 1 =
  // vertex j) instead of being formed from per-constraint Jacobians.
  int64_t constraint_count;
  const double* term_sums;
};

// The registration term's share of a diagonal block entry / gradient entry / off-diagonal entry.
COVOX_HD_INLINE const double* registration_term_sums(const StructureView& s, int64_t k) {
  return s.term_sums + (k - s.constraint_count) * kRegistrationSumStride;
}

// Diagonal blocks and gradient g = J^T f. One thread per matrix entry: a sum over that vertex's
// terms in list order, so both backends add in the same order.
template <int D, class Backend>
void assemble_diagonal_and_gradient(Backend backend, const Stream& stream, StructureView s,
                                    const double* jac_from, const double* jac_to,
                                    const double* residuals, double* hessian_diag,
                                    double* gradient) {
  constexpr int DD = D * D;
  parallel_for(backend, stream, static_cast<int64_t>(s.vertex_count) * DD, [=] COVOX_HD(int64_t t) {
    const int64_t v = t / DD;
    const int r = static_cast<int>(t % DD) / D, c = static_cast<int>(t % DD) % D;
    double sum = 0.0;
    if (v == s.fixed_vertex) {
      sum = r == c ? 1.0 : 0.0;
    } else {
      for (int32_t e = s.diag_offsets[v]; e < s.diag_offsets[v + 1]; ++e) {
        const int32_t term = s.diag_terms[e];
        if ((term >> 1) >= s.constraint_count) {
          const double* h = registration_term_sums(s, term >> 1);
          sum += h[((term & 1) ? kRegistrationHjjOffset : kRegistrationHiiOffset) + r * D + c];
          continue;
        }
        const double* j = ((term & 1) ? jac_to : jac_from) + static_cast<int64_t>(term >> 1) * DD;
        for (int k = 0; k < D; ++k) sum += j[k * D + r] * j[k * D + c];
      }
    }
    hessian_diag[t] = sum;
  });
  parallel_for(backend, stream, static_cast<int64_t>(s.vertex_count) * D, [=] COVOX_HD(int64_t t) {
    const int64_t v = t / D;
    const int r = static_cast<int>(t % D);
    double sum = 0.0;
    if (v != s.fixed_vertex) {
      for (int32_t e = s.diag_offsets[v]; e < s.diag_offsets[v + 1]; ++e) {
        const int32_t term = s.diag_terms[e];
        const int64_t k_constraint = term >> 1;
        if (k_constraint >= s.constraint_count) {
          const double* h = registration_term_sums(s, k_constraint);
          sum += h[((term & 1) ? kRegistrationGjOffset : kRegistrationGiOffset) + r];
          continue;
        }
        const double* j = ((term & 1) ? jac_to : jac_from) + k_constraint * DD;
        const double* f = residuals + k_constraint * D;
        for (int k = 0; k < D; ++k) sum += j[k * D + r] * f[k];
      }
    }
    gradient[t] = sum;
  });
}

// Off-diagonal blocks H(row, col) = sum Jrow^T Jcol.
template <int D, class Backend>
void assemble_off_diagonal(Backend backend, const Stream& stream, StructureView s,
                           const double* jac_from, const double* jac_to, double* hessian_off) {
  constexpr int DD = D * D;
  parallel_for(backend, stream, s.off_block_count * DD, [=] COVOX_HD(int64_t t) {
    const int64_t b = t / DD;
    const int r = static_cast<int>(t % DD) / D, c = static_cast<int>(t % DD) % D;
    double sum = 0.0;
    for (int32_t e = s.off_offsets[b]; e < s.off_offsets[b + 1]; ++e) {
      const int32_t term = s.off_terms[e];
      if ((term >> 1) >= s.constraint_count) {
        // H(row, col) is H_ij when i = row, else H_ij^T (H_ji).
        const double* h = registration_term_sums(s, term >> 1) + kRegistrationHijOffset;
        sum += (term & 1) ? h[c * D + r] : h[r * D + c];
        continue;
      }
      const int64_t offset = static_cast<int64_t>(term >> 1) * DD;
      const double* j_row = ((term & 1) ? jac_to : jac_from) + offset;
      const double* j_col = ((term & 1) ? jac_from : jac_to) + offset;
      for (int k = 0; k < D; ++k) sum += j_row[k * D + r] * j_col[k * D + c];
    }
    hessian_off[t] = sum;
  });
}

// a^-1 for a symmetric positive definite D x D matrix, through its Cholesky factor. Returns false
// (leaving `inverse` unspecified) when a pivot is not positive.
template <int D>
COVOX_HD_INLINE bool invert_spd(const double* matrix, double* inverse) {
  double a[D * D];
  for (int k = 0; k < D * D; ++k) a[k] = matrix[k];
  // In place: the lower triangle of `a` becomes L with L L^T = matrix.
  for (int j = 0; j < D; ++j) {
    double diag = a[j * D + j];
    for (int k = 0; k < j; ++k) diag -= a[j * D + k] * a[j * D + k];
    if (!(diag > 0.0)) return false;
    diag = sqrt(diag);
    a[j * D + j] = diag;
    for (int i = j + 1; i < D; ++i) {
      double x = a[i * D + j];
      for (int k = 0; k < j; ++k) x -= a[i * D + k] * a[j * D + k];
      a[i * D + j] = x / diag;
    }
  }
  // Columns of the inverse: solve L y = e_c, then L^T x = y.
  for (int c = 0; c < D; ++c) {
    double y[D];
    for (int i = 0; i < D; ++i) {
      double x = i == c ? 1.0 : 0.0;
      for (int k = 0; k < i; ++k) x -= a[i * D + k] * y[k];
      y[i] = x / a[i * D + i];
    }
    for (int i = D - 1; i >= 0; --i) {
      double x = y[i];
      for (int k = i + 1; k < D; ++k) x -= a[k * D + i] * y[k];
      y[i] = x / a[i * D + i];
    }
    for (int i = 0; i < D; ++i) inverse[i * D + c] = y[i];
  }
  return true;
}

// The inverse of the diagonal of `matrix` (the fallback when rounding makes a block indefinite).
template <int D>
COVOX_HD_INLINE void invert_diagonal(const double* matrix, double* inverse) {
  for (int r = 0; r < D; ++r) {
    for (int c = 0; c < D; ++c) {
      const double d = matrix[r * D + r];
      inverse[r * D + c] = (r == c && d > 0.0) ? 1.0 / d : 0.0;
    }
  }
}

// LM damping as in Ceres: lambda_i = clamp(H_ii, min_diagonal, max_diagonal) / radius, and the
// block-Jacobi preconditioner: the inverse of each damped diagonal block.
template <int D, class Backend>
void damping_and_preconditioner(Backend backend, const Stream& stream, int32_t vertex_count,
                                const double* hessian_diag, double radius, double min_diagonal,
                                double max_diagonal, double* damping, double* preconditioner) {
  constexpr int DD = D * D;
  parallel_for(backend, stream, vertex_count, [=] COVOX_HD(int64_t v) {
    const double* h = hessian_diag + v * DD;
    double a[DD];
    for (int k = 0; k < DD; ++k) a[k] = h[k];
    for (int r = 0; r < D; ++r) {
      double d = h[r * D + r];
      d = d < min_diagonal ? min_diagonal : (d > max_diagonal ? max_diagonal : d);
      damping[v * D + r] = d / radius;
      a[r * D + r] += d / radius;
    }
    double* inv = preconditioner + v * DD;
    if (!invert_spd<D>(a, inv)) invert_diagonal<D>(a, inv);
  });
}

// The chain preconditioner's segments: runs of `segment_vertices` consecutive vertices, the last
// one shorter. Segment `segment` holds the vertices [begin, end).
struct ChainSegment {
  int32_t begin;
  int32_t end;
};
COVOX_HD_INLINE int32_t chain_segment_count(int32_t vertex_count, int32_t segment_vertices) {
  return (vertex_count + segment_vertices - 1) / segment_vertices;
}
COVOX_HD_INLINE ChainSegment chain_segment(int64_t segment, int32_t vertex_count,
                                           int32_t segment_vertices) {
  const int32_t begin = static_cast<int32_t>(segment) * segment_vertices;
  const int32_t end =
      begin + segment_vertices < vertex_count ? begin + segment_vertices : vertex_count;
  return ChainSegment{begin, end};
}

// The off-diagonal block (v - 1, v) of H that the chain keeps inside `segment`, or null where v
// starts the segment (links between segments are dropped) or no constraint joins v - 1 and v.
template <int D>
COVOX_HD_INLINE const double* chain_block_before(int32_t v, const ChainSegment& segment,
                                                 const int32_t* chain_blocks,
                                                 const double* hessian_off) {
  const int32_t previous = v > segment.begin ? chain_blocks[v - 1] : -1;
  return previous >= 0 ? hessian_off + static_cast<int64_t>(previous) * D * D : nullptr;
}

// The odometry-chain preconditioner: M = the block-tridiagonal part of H + damping in vertex
// order (blocks (v, v) and (v, v + 1)), cut into segments of `segment_vertices` consecutive
// vertices (the links between segments are dropped). Each constraint's term of H is positive
// semi-definite and dropping the off-diagonal part of a term keeps it so, hence M is positive
// definite. It holds the long, weakly stiff chains of a pose graph that block-Jacobi cannot, which
// is what makes CG slow on them. Each segment is factorised by the block Thomas algorithm (block
// LDL^T): a sequential sweep in one device thread per segment (O(L D^3)). One segment spanning
// the whole graph is the exact chain (fewest CG iterations, no parallelism); on a GPU a single
// thread sweeping a thousand vertices costs more per CG iteration than the iterations it saves,
// so segments of a few dozen vertices keep the sweep parallel while still holding most of the
// chain. `chain_blocks[v]` is the off-diagonal block (v, v + 1) or -1; `schur_inverse` receives
// S_v^-1 with S_v = M_vv - B_{v-1}^T S_{v-1}^-1 B_{v-1}.
template <int D, class Backend>
void factorize_chain(Backend backend, const Stream& stream, int32_t vertex_count,
                     int32_t segment_vertices, const double* hessian_diag,
                     const double* hessian_off, const double* damping, const int32_t* chain_blocks,
                     double* schur_inverse) {
  constexpr int DD = D * D;
  const int32_t segments = chain_segment_count(vertex_count, segment_vertices);
  parallel_for(backend, stream, segments, [=] COVOX_HD(int64_t segment) {
    const ChainSegment range = chain_segment(segment, vertex_count, segment_vertices);
    for (int32_t v = range.begin; v < range.end; ++v) {
      double s[DD];
      for (int k = 0; k < DD; ++k) s[k] = hessian_diag[static_cast<int64_t>(v) * DD + k];
      for (int r = 0; r < D; ++r) s[r * D + r] += damping[static_cast<int64_t>(v) * D + r];
      const double* b = chain_block_before<D>(v, range, chain_blocks, hessian_off);
      if (b != nullptr) {
        const double* p = schur_inverse + static_cast<int64_t>(v - 1) * DD;
        // s -= B^T P B, with t = P B first.
        double t[DD];
        for (int r = 0; r < D; ++r) {
          for (int c = 0; c < D; ++c) {
            double x = 0.0;
            for (int k = 0; k < D; ++k) x += p[r * D + k] * b[k * D + c];
            t[r * D + c] = x;
          }
        }
        for (int r = 0; r < D; ++r) {
          for (int c = 0; c < D; ++c) {
            double x = 0.0;
            for (int k = 0; k < D; ++k) x += b[k * D + r] * t[k * D + c];
            s[r * D + c] -= x;
          }
        }
      }
      double* inv = schur_inverse + static_cast<int64_t>(v) * DD;
      if (!invert_spd<D>(s, inv)) invert_diagonal<D>(s, inv);
    }
  });
}

// y = M^-1 x for the chain preconditioner (forward and backward block substitution per segment).
template <int D, class Backend>
void apply_chain_preconditioner(Backend backend, const Stream& stream, int32_t vertex_count,
                                int32_t segment_vertices, const double* hessian_off,
                                const int32_t* chain_blocks, const double* schur_inverse,
                                const double* x, double* y) {
  constexpr int DD = D * D;
  const int32_t segments = chain_segment_count(vertex_count, segment_vertices);
  parallel_for(backend, stream, segments, [=] COVOX_HD(int64_t segment) {
    const ChainSegment range = chain_segment(segment, vertex_count, segment_vertices);
    // Forward: z_v = x_v - B_{v-1}^T w_{v-1}, w_v = S_v^-1 z_v (w stored in y).
    for (int32_t v = range.begin; v < range.end; ++v) {
      double z[D];
      for (int r = 0; r < D; ++r) z[r] = x[static_cast<int64_t>(v) * D + r];
      const double* b = chain_block_before<D>(v, range, chain_blocks, hessian_off);
      if (b != nullptr) {
        const double* w = y + static_cast<int64_t>(v - 1) * D;
        for (int r = 0; r < D; ++r) {
          for (int k = 0; k < D; ++k) z[r] -= b[k * D + r] * w[k];
        }
      }
      const double* p = schur_inverse + static_cast<int64_t>(v) * DD;
      for (int r = 0; r < D; ++r) {
        double sum = 0.0;
        for (int k = 0; k < D; ++k) sum += p[r * D + k] * z[k];
        y[static_cast<int64_t>(v) * D + r] = sum;
      }
    }
    // Backward: y_v = w_v - S_v^-1 B_v y_{v+1}.
    for (int32_t v = range.end - 2; v >= range.begin; --v) {
      const int32_t block = chain_blocks[v];
      if (block < 0) continue;
      const double* b = hessian_off + static_cast<int64_t>(block) * DD;
      const double* next = y + static_cast<int64_t>(v + 1) * D;
      double t[D];
      for (int r = 0; r < D; ++r) {
        double sum = 0.0;
        for (int k = 0; k < D; ++k) sum += b[r * D + k] * next[k];
        t[r] = sum;
      }
      const double* p = schur_inverse + static_cast<int64_t>(v) * DD;
      for (int r = 0; r < D; ++r) {
        double sum = 0.0;
        for (int k = 0; k < D; ++k) sum += p[r * D + k] * t[k];
        y[static_cast<int64_t>(v) * D + r] -= sum;
      }
    }
  });
}

// y = (H + diag(damping)) x, one thread per row; `damping` may be null (undamped H).
template <int D, class Backend>
void multiply_normal_matrix(Backend backend, const Stream& stream, StructureView s,
                            const double* hessian_diag, const double* hessian_off,
                            const double* damping, const double* x, double* y) {
  constexpr int DD = D * D;
  parallel_for(backend, stream, static_cast<int64_t>(s.vertex_count) * D, [=] COVOX_HD(int64_t t) {
    const int64_t v = t / D;
    const int r = static_cast<int>(t % D);
    const double* h = hessian_diag + v * DD + r * D;
    const double* xv = x + v * D;
    double sum = damping ? damping[t] * x[t] : 0.0;
    for (int c = 0; c < D; ++c) sum += h[c] * xv[c];
    for (int32_t e = s.row_offsets[v]; e < s.row_offsets[v + 1]; ++e) {
      const int32_t entry = s.row_entries[e];
      const double* block = hessian_off + static_cast<int64_t>(entry >> 1) * DD;
      const double* xc = x + static_cast<int64_t>(s.row_columns[e]) * D;
      if (entry & 1) {
        for (int c = 0; c < D; ++c) sum += block[c * D + r] * xc[c];  // H(col, row)^T
      } else {
        for (int c = 0; c < D; ++c) sum += block[r * D + c] * xc[c];
      }
    }
    y[t] = sum;
  });
}

// y = M^-1 x with the block-diagonal preconditioner.
template <int D, class Backend>
void apply_preconditioner(Backend backend, const Stream& stream, int32_t vertex_count,
                          const double* preconditioner, const double* x, double* y) {
  constexpr int DD = D * D;
  parallel_for(backend, stream, static_cast<int64_t>(vertex_count) * D, [=] COVOX_HD(int64_t t) {
    const int64_t v = t / D;
    const int r = static_cast<int>(t % D);
    const double* m = preconditioner + v * DD + r * D;
    const double* xv = x + v * D;
    double sum = 0.0;
    for (int c = 0; c < D; ++c) sum += m[c] * xv[c];
    y[t] = sum;
  });
}

template <class Model, class Backend>
void plus_poses(Backend backend, const Stream& stream, int32_t vertex_count,
                const typename Model::Pose* poses, const double* delta, typename Model::Pose* out) {
  parallel_for(backend, stream, vertex_count, [=] COVOX_HD(int64_t v) {
    out[v] = Model::plus(poses[v], delta + v * Model::kDim);
  });
}

// Vector helpers over `count` doubles; `indices` holds 0, 1, ..., count - 1 (a device iota that
// lets transform_reduce read two arrays at once).
template <class Backend>
double dot(Backend backend, const Stream& stream, const int64_t* indices, int64_t count,
           const double* x, const double* y) {
  return transform_reduce(
      backend, stream, indices, count, [=] COVOX_HD(int64_t i) { return x[i] * y[i]; }, 0.0,
      thrust::plus<double>());
}

template <class Backend>
double max_abs(Backend backend, const Stream& stream, const int64_t* indices, int64_t count,
               const double* x) {
  return transform_reduce(
      backend, stream, indices, count,
      [=] COVOX_HD(int64_t i) { return x[i] < 0.0 ? -x[i] : x[i]; }, 0.0,
      thrust::maximum<double>());
}

}  // namespace backend
}  // namespace covox

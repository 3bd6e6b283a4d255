#pragma once
// The scalar side of preconditioned conjugate gradients kept in the device's memory, written once
// for both backends (included through pose_graph_solver_impl.h). Each of an iteration's three dot
// products decides the next step (its length, whether to stop, the next direction); read back,
// each would be a wait between small kernels, which on a pose graph of a few thousand unknowns
// costs more than the kernels. Here they are reduced into a CgState in the device's memory where
// the kernels read them: the host enqueues iterations without waiting and reads the state only
// every few iterations. Once CG has stopped, the iterations already enqueued change nothing, so
// the result is that of a loop that tests after every iteration.
#include <cmath>
#include <cstdint>

#include <thrust/functional.h>

#include "covoxslam/core/macros.h"
#include "covoxslam/core/parallel.h"

namespace covox {
namespace backend {

// One iteration, in order (each line one kernel or reduction):
//   q = A p                                 (the caller's matrix product)
//   pq = p.q
//   cg_update:    x += (rz / pq) p, r -= (rz / pq) q      unless stopped or pq <= 0
//   rr = r.r
//   z = M^-1 r                              (the caller's preconditioner)
//   rz_next = r.z
//   cg_advance:   counts the iteration; stops on pq <= 0 or |r| <= tolerance |b|, else beta
//   cg_direction: p = z + beta p            unless stopped
// `stopped` is written only by cg_start and cg_advance, single-thread kernels, so no kernel reads
// a flag that it or a kernel running beside it writes.
struct CgState {
  double rz = 0.0;       // r.z of the current residual and preconditioned residual
  double rz_next = 0.0;  // r.z after this iteration's update
  double pq = 0.0;       // p.A p
  double rr = 0.0;       // r.r after this iteration's update (before the first: b.b)
  double b_norm = 0.0;   // |b| = |r| at the start
  double beta = 0.0;
  int32_t iterations = 0;
  int32_t stopped = 0;
};

// out = x.y over `count` entries, left in the device's memory; `indices` holds 0 .. count - 1.
template <class Backend>
void dot_into(Backend backend, const Stream& stream, const int64_t* indices, int64_t count,
              const double* x, const double* y, double* out) {
  transform_reduce_into(
      backend, stream, indices, count, [=] COVOX_HD(int64_t i) { return x[i] * y[i]; }, 0.0,
      thrust::plus<double>(), out);
}

// After rr = b.b: a fresh state, already stopped when b = 0 (the step is then x = 0).
template <class Backend>
void cg_start(Backend backend, const Stream& stream, CgState* state) {
  parallel_for(backend, stream, 1, [=] COVOX_HD(int64_t) {
    state->b_norm = sqrt(state->rr);
    state->iterations = 0;
    state->stopped = state->b_norm == 0.0 ? 1 : 0;
  });
}

template <class Backend>
void cg_update(Backend backend, const Stream& stream, int64_t count, const CgState* state,
               const double* p, const double* q, double* x, double* r) {
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    if (state->stopped || !(state->pq > 0.0)) return;
    const double alpha = state->rz / state->pq;
    x[i] += alpha * p[i];
    r[i] -= alpha * q[i];
  });
}

// Stops when p.A p is no longer positive (no descent direction left: rounding at convergence) or
// the residual has fallen to relative_tolerance |b|.
template <class Backend>
void cg_advance(Backend backend, const Stream& stream, double relative_tolerance, CgState* state) {
  parallel_for(backend, stream, 1, [=] COVOX_HD(int64_t) {
    if (state->stopped) return;
    ++state->iterations;
    if (!(state->pq > 0.0) || sqrt(state->rr) <= relative_tolerance * state->b_norm) {
      state->stopped = 1;
      return;
    }
    state->beta = state->rz_next / state->rz;
    state->rz = state->rz_next;
  });
}

template <class Backend>
void cg_direction(Backend backend, const Stream& stream, int64_t count, const CgState* state,
                  const double* z, double* p) {
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    if (state->stopped) return;
    p[i] = z[i] + state->beta * p[i];
  });
}

}  // namespace backend
}  // namespace covox

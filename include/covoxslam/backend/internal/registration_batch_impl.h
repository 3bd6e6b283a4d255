#pragma once
// Batched pair registration's sums (registration_batch_ops.h), written once for both backends and
// instantiated by COVOX_INSTANTIATE_REGISTRATION_BATCH.
#include "covoxslam/backend/internal/registration_batch_ops.h"
#include "covoxslam/backend/internal/registration_terms_ops.h"
#include "covoxslam/core/parallel.h"

namespace covox {
namespace backend {

template <class Backend>
void registration_batch_chunk_sums(Backend backend, const Stream& stream,
                                   const RegistrationBatchTerm* terms,
                                   const RegistrationDistanceLookup* fields,
                                   const int32_t* chunk_term, const int64_t* chunk_begin,
                                   const int64_t* chunk_end, int64_t chunk_count,
                                   double* chunk_sums) {
  parallel_for(backend, stream, chunk_count, [=] COVOX_HD(int64_t chunk) {
    double sum[kRegistrationBatchSumStride];
    for (int k = 0; k < kRegistrationBatchSumStride; ++k) sum[k] = 0.0;
    const RegistrationBatchTerm& term = terms[chunk_term[chunk]];
    if (term.active) {
      const RegistrationDistanceLookup& field = fields[term.field];
      for (int64_t p = chunk_begin[chunk]; p < chunk_end[chunk]; ++p) {
        const RegistrationResidual r =
            registration_scaled_residual(term.points[p], field, term.geometry, term.robust,
                                         term.tsdf_target != 0, term.inverse_sigma);
        if (!r.valid) continue;
        const double* jacobian = term.field_pose ? r.jacobian_j : r.jacobian_i;
        int k = 0;
        for (int row = 0; row < 4; ++row) {
          const double weighted = r.robust_weight * jacobian[row];
          for (int col = row; col < 4; ++col) sum[k++] += weighted * jacobian[col];
          sum[kRegistrationBatchGradientOffset + row] += weighted * r.residual;
        }
        sum[kRegistrationBatchCostOffset] += r.cost;
        sum[kRegistrationBatchUsedOffset] += 1.0;
      }
    }
    double* out = chunk_sums + chunk * kRegistrationBatchSumStride;
    for (int k = 0; k < kRegistrationBatchSumStride; ++k) out[k] = sum[k];
  });
}

template <class Backend>
void registration_batch_sum_rows(Backend backend, const Stream& stream, const int64_t* row_offsets,
                                 int64_t out_rows, const double* in, double* out) {
  parallel_for(backend, stream, out_rows * kRegistrationBatchSumStride, [=] COVOX_HD(int64_t task) {
    const int64_t row = task / kRegistrationBatchSumStride;
    const int entry = static_cast<int>(task % kRegistrationBatchSumStride);
    double sum = 0.0;
    for (int64_t r = row_offsets[row]; r < row_offsets[row + 1]; ++r)
      sum += in[r * kRegistrationBatchSumStride + entry];
    out[task] = sum;
  });
}

#define COVOX_INSTANTIATE_REGISTRATION_BATCH(Backend)                                          \
  template void registration_batch_chunk_sums<Backend>(                                        \
      Backend, const Stream&, const RegistrationBatchTerm*, const RegistrationDistanceLookup*, \
      const int32_t*, const int64_t*, const int64_t*, int64_t, double*);                       \
  template void registration_batch_sum_rows<Backend>(Backend, const Stream&, const int64_t*,   \
                                                     int64_t, const double*, double*);

}  // namespace backend
}  // namespace covox

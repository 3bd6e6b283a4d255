#pragma once
// The data-parallel step of batched pair registration (registration_batch.h): the IRLS sums of
// many registration terms at once, for both backends (defined in registration_batch_impl.h). A
// term is one direction of one pair: the points of one submap in the field of the other, summed
// with respect to one of the two poses. The sums are a tree of fixed shape: a thread sums a chunk
// of at most kRegistrationBatchChunkPoints consecutive points of a term in order, then each level
// sums runs of at most kRegistrationBatchFanIn consecutive rows of a term in order, until one row
// per term is left. No run crosses a term, so the order is fixed, the same on both backends, and
// a term's sums do not depend on which other terms share the batch.
#include <cstdint>

#include "covoxslam/backend/internal/registration_ops.h"

namespace covox {
namespace backend {

constexpr int64_t kRegistrationBatchChunkPoints = 4;
constexpr int64_t kRegistrationBatchFanIn = 32;

// Per term (and per chunk), kRegistrationBatchSumStride doubles: the upper triangle of the 4x4
// Hessian (row-major), the gradient, the cost and the points inside the field.
constexpr int kRegistrationBatchSumStride = 16;
constexpr int kRegistrationBatchGradientOffset = 10;
constexpr int kRegistrationBatchCostOffset = 14;
constexpr int kRegistrationBatchUsedOffset = 15;

struct RegistrationBatchTerm {
  const RegistrationPoint* points = nullptr;  // this term's points (device memory)
  int32_t field = 0;                          // index into the array of field lookups
  uint8_t active = 0;                         // 0: sums of zero, no lookups
  uint8_t tsdf_target = 0;
  // 1: the sums are with respect to the field's pose (jacobian_j), 0: the points' (jacobian_i).
  uint8_t field_pose = 0;
  double inverse_sigma = 1.0;  // residuals and Jacobians are multiplied by this before the loss
  RobustLossParams robust;
  RegistrationPairGeometry geometry;
};

// Level 1: chunk c holds points [chunk_begin[c], chunk_end[c]) of term chunk_term[c] (indices
// into that term's points); chunk_sums: chunk_count rows of kRegistrationBatchSumStride.
template <class Backend>
void registration_batch_chunk_sums(Backend backend, const Stream& stream,
                                   const RegistrationBatchTerm* terms,
                                   const RegistrationDistanceLookup* fields,
                                   const int32_t* chunk_term, const int64_t* chunk_begin,
                                   const int64_t* chunk_end, int64_t chunk_count,
                                   double* chunk_sums);

// A level above: output row r sums input rows [row_offsets[r], row_offsets[r + 1]) in order.
template <class Backend>
void registration_batch_sum_rows(Backend backend, const Stream& stream, const int64_t* row_offsets,
                                 int64_t out_rows, const double* in, double* out);

}  // namespace backend
}  // namespace covox

#include "covoxslam/backend/registration_batch.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "covoxslam/backend/internal/registration_batch_ops.h"
#include "covoxslam/backend/internal/registration_lm.h"
#include "covoxslam/core/error.h"

namespace covox {
namespace backend {
namespace {

void check_pair(const RegistrationBatchPair& pair, size_t index, Device device) {
  const std::string which = "registration batch: pair " + std::to_string(index);
  if ((pair.points_j == nullptr) != (pair.map_i == nullptr)) {
    throw Error(which + ": points_j and map_i come together (both for a symmetric pair, neither " +
                "for a one-way one)");
  }
  if (!(pair.reverse_weight_scale > 0.0 && std::isfinite(pair.reverse_weight_scale))) {
    throw Error(which + ": reverse_weight_scale must be finite and > 0, got " +
                std::to_string(pair.reverse_weight_scale));
  }
  const bool same_device =
      pair.points_i->points.device() == device && pair.map_j->device() == device &&
      (!pair.map_i || (pair.map_i->device() == device && pair.points_j->points.device() == device));
  if (!same_device) {
    throw Error(which + " has points or maps on another device than " + to_string(device) +
                "; a batch runs on one device");
  }
  const Pose4Dof& s = pair.start_T_Sj_Si;
  if (!(std::isfinite(s.x) && std::isfinite(s.y) && std::isfinite(s.z) && std::isfinite(s.yaw))) {
    throw Error(which + ": the start pose is not finite");
  }
}

// The residual settings of a level: 0 the fine residual, L >= 1 the ESDF every 2^L voxels.
RegistrationResidualConfig level_config(const RegistrationResidualConfig& fine, int level) {
  RegistrationResidualConfig config = fine;
  if (level > 0) config.coarse_stride_vox = 1 << level;
  return config;
}

// The batch on its device: every pair's terms (forward, and reverse when symmetric), their
// points indexed, a field lookup per term and level, and the buffers of one evaluation round.
class RegistrationBatch {
 public:
  RegistrationBatch(const std::vector<RegistrationBatchPair>& pairs,
                    const RegistrationResidualConfig& fine, int levels, const Stream& stream)
      : pairs_(pairs), fine_(fine), levels_(levels), stream_(stream) {
    for (size_t p = 0; p < pairs.size(); ++p) {
      if (!pairs[p].points_i || !pairs[p].map_j) {
        throw Error("registration batch: pair " + std::to_string(p) + " needs points_i and map_j");
      }
    }
    device_ = pairs.empty() ? Device::kCpu : pairs.front().map_j->device();
    for (size_t p = 0; p < pairs.size(); ++p) check_pair(pairs[p], p, device_);
    validate_registration_residual_config(fine);
    std::vector<RegistrationDistanceLookup> fields;
    for (const RegistrationBatchPair& pair : pairs) {
      add_term(*pair.points_i, *pair.map_j, &fields);
      if (pair.map_i) add_term(*pair.points_j, *pair.map_i, &fields);
    }
    fields_ = Buffer<RegistrationDistanceLookup>::from_host(device_, fields, stream);
    build_sum_tree();
    terms_ = Buffer<RegistrationBatchTerm>(device_, host_terms_.size());
  }

  // Each pair's sums at its request (null: the pair is idle and its entry is left as it was).
  void evaluate(const std::vector<const RegistrationLmRequest*>& requests,
                std::vector<RegistrationNormalEquations>* sums) {
    size_t term = 0;
    for (size_t p = 0; p < pairs_.size(); ++p) {
      const RegistrationLmRequest* request = requests[p];
      set_term(&host_terms_[term++], request, request ? request->pose : Pose4Dof(), Pose4Dof(),
               false, 1.0);
      if (!pairs_[p].map_i) continue;
      // Submap j's points, pose fixed at the origin, in submap i's field at T_Sj_Si: the sums
      // with respect to the field's pose are those with respect to T_Sj_Si. Multiplying the
      // residuals by sqrt(k) multiplies the terms by k and the robust loss sees them so scaled.
      set_term(&host_terms_[term++], request && !request->forward_only ? request : nullptr,
               Pose4Dof(), request ? request->pose : Pose4Dof(), true,
               std::sqrt(pairs_[p].reverse_weight_scale));
    }
    const std::vector<double> term_sums = run();
    term = 0;
    for (size_t p = 0; p < pairs_.size(); ++p) {
      const double* forward = term_sums.data() + term * kRegistrationBatchSumStride;
      const int64_t forward_points = term_points_[term++];
      if (!requests[p]) {
        if (pairs_[p].map_i) ++term;
        continue;
      }
      RegistrationNormalEquations out = unpack(forward, forward_points);
      if (pairs_[p].map_i) {
        const double* reverse = term_sums.data() + term * kRegistrationBatchSumStride;
        const int64_t reverse_points = term_points_[term++];
        if (!requests[p]->forward_only) out = sum_of(out, unpack(reverse, reverse_points));
      }
      (*sums)[p] = out;
    }
  }

 private:
  void add_term(const RegistrationPoints& points, const map::TsdfMap& field_map,
                std::vector<RegistrationDistanceLookup>* fields) {
    RegistrationBatchTerm term;
    term.points = points.points.data();
    term.field = static_cast<int32_t>(fields->size());
    for (int level = 0; level <= levels_; ++level) {
      fields->push_back(make_registration_lookup(field_map, level_config(fine_, level)));
    }
    host_terms_.push_back(term);
    first_fields_.push_back(term.field);
    term_points_.push_back(static_cast<int64_t>(points.points.size()));
  }

  // The shape of the sums (registration_batch_ops.h): chunks of each term's points (one empty
  // chunk for a term without points, so that every term has a row), then levels of runs of at
  // most kRegistrationBatchFanIn rows of one term until a row per term is left.
  void build_sum_tree() {
    std::vector<int32_t> chunk_term;
    std::vector<int64_t> chunk_begin, chunk_end;
    std::vector<int64_t> term_rows{0};  // term t's rows: [term_rows[t], term_rows[t + 1])
    for (size_t t = 0; t < host_terms_.size(); ++t) {
      const int64_t n = term_points_[t];
      for (int64_t begin = 0; begin < std::max<int64_t>(n, 1);
           begin += kRegistrationBatchChunkPoints) {
        chunk_term.push_back(static_cast<int32_t>(t));
        chunk_begin.push_back(begin);
        chunk_end.push_back(std::min(n, begin + kRegistrationBatchChunkPoints));
      }
      term_rows.push_back(static_cast<int64_t>(chunk_term.size()));
    }
    chunk_term_ = Buffer<int32_t>::from_host(device_, chunk_term, stream_);
    chunk_begin_ = Buffer<int64_t>::from_host(device_, chunk_begin, stream_);
    chunk_end_ = Buffer<int64_t>::from_host(device_, chunk_end, stream_);
    level_sums_.emplace_back(device_, chunk_term.size() * kRegistrationBatchSumStride);
    for (;;) {
      bool reduced = true;
      std::vector<int64_t> offsets{0}, next_rows{0};
      for (size_t t = 0; t + 1 < term_rows.size(); ++t) {
        reduced = reduced && term_rows[t + 1] - term_rows[t] == 1;
        for (int64_t row = term_rows[t]; row < term_rows[t + 1]; row += kRegistrationBatchFanIn)
          offsets.push_back(std::min(term_rows[t + 1], row + kRegistrationBatchFanIn));
        next_rows.push_back(static_cast<int64_t>(offsets.size()) - 1);
      }
      if (reduced) break;
      level_offsets_.push_back(Buffer<int64_t>::from_host(device_, offsets, stream_));
      level_sums_.emplace_back(device_, (offsets.size() - 1) * kRegistrationBatchSumStride);
      term_rows = next_rows;
    }
  }

  void set_term(RegistrationBatchTerm* term, const RegistrationLmRequest* request,
                const Pose4Dof& T_W_points, const Pose4Dof& T_W_field, bool field_pose,
                double inverse_sigma) {
    term->active = request ? 1 : 0;
    if (!request) return;
    const RegistrationResidualConfig config = level_config(fine_, request->level);
    const size_t index = static_cast<size_t>(term - host_terms_.data());
    term->field = first_fields_[index] + request->level;
    term->tsdf_target = registration_uses_tsdf_target(config) ? 1 : 0;
    term->field_pose = field_pose ? 1 : 0;
    term->inverse_sigma = inverse_sigma;
    term->robust = RobustLossParams{config.loss, config.loss_scale};
    term->geometry = registration_pair_geometry(T_W_points, T_W_field);
  }

  std::vector<double> run() {
    const int64_t term_count = static_cast<int64_t>(host_terms_.size());
    if (term_count == 0) return {};
    copy_bytes(terms_.data(), device_, host_terms_.data(), Device::kCpu, terms_.size_bytes(),
               stream_);
    dispatch(device_, [&](auto backend) {
      registration_batch_chunk_sums(
          backend, stream_, terms_.data(), fields_.data(), chunk_term_.data(), chunk_begin_.data(),
          chunk_end_.data(), static_cast<int64_t>(chunk_term_.size()), level_sums_.front().data());
      for (size_t level = 0; level < level_offsets_.size(); ++level) {
        registration_batch_sum_rows(backend, stream_, level_offsets_[level].data(),
                                    static_cast<int64_t>(level_offsets_[level].size()) - 1,
                                    level_sums_[level].data(), level_sums_[level + 1].data());
      }
    });
    return level_sums_.back().to_host(stream_);
  }

  static RegistrationNormalEquations unpack(const double* s, int64_t points) {
    return normal_equations_from_sums(
        s, s + kRegistrationBatchGradientOffset, s[kRegistrationBatchCostOffset],
        static_cast<int64_t>(s[kRegistrationBatchUsedOffset]), points);
  }

  const std::vector<RegistrationBatchPair>& pairs_;
  RegistrationResidualConfig fine_;
  int levels_;
  const Stream& stream_;
  Device device_ = Device::kCpu;
  std::vector<RegistrationBatchTerm> host_terms_;
  std::vector<int32_t> first_fields_;
  std::vector<int64_t> term_points_;
  Buffer<RegistrationDistanceLookup> fields_;
  Buffer<int32_t> chunk_term_;
  Buffer<int64_t> chunk_begin_, chunk_end_;
  std::vector<Buffer<int64_t>> level_offsets_;  // one per level above the chunks
  std::vector<Buffer<double>> level_sums_;      // the chunks' sums, then each level's
  Buffer<RegistrationBatchTerm> terms_;
};

}  // namespace

std::vector<RegistrationNormalEquations> registration_batch_normal_equations(
    const std::vector<RegistrationBatchPair>& pairs, const std::vector<Pose4Dof>& poses_T_Sj_Si,
    const RegistrationResidualConfig& config, const Stream& stream) {
  if (poses_T_Sj_Si.size() != pairs.size()) {
    throw Error("registration batch: " + std::to_string(poses_T_Sj_Si.size()) + " poses for " +
                std::to_string(pairs.size()) + " pairs");
  }
  RegistrationBatch batch(pairs, config, 0, stream);
  std::vector<RegistrationLmRequest> requests(pairs.size());
  std::vector<const RegistrationLmRequest*> pointers(pairs.size());
  for (size_t p = 0; p < pairs.size(); ++p) {
    requests[p].pose = poses_T_Sj_Si[p];
    pointers[p] = &requests[p];
  }
  std::vector<RegistrationNormalEquations> sums(pairs.size());
  batch.evaluate(pointers, &sums);
  return sums;
}

std::vector<RegistrationBatchOutcome> align_submap_pairs(
    const std::vector<RegistrationBatchPair>& pairs, const RegistrationAlignerConfig& config,
    const Stream& stream, int64_t min_points_at_start) {
  std::vector<RegistrationLm> aligners;
  aligners.reserve(pairs.size());
  for (const RegistrationBatchPair& pair : pairs) {
    aligners.emplace_back(pair.start_T_Sj_Si, config, min_points_at_start);
  }
  RegistrationBatch batch(pairs, config.residual, config.coarse_levels, stream);
  std::vector<const RegistrationLmRequest*> requests(pairs.size());
  std::vector<RegistrationNormalEquations> sums(pairs.size());
  // Rounds until every pair has finished: each evaluates all open requests at once.
  for (;;) {
    bool open = false;
    for (size_t p = 0; p < pairs.size(); ++p) {
      requests[p] = aligners[p].done() ? nullptr : &aligners[p].request();
      open = open || requests[p] != nullptr;
    }
    if (!open) break;
    batch.evaluate(requests, &sums);
    for (size_t p = 0; p < pairs.size(); ++p) {
      if (requests[p]) aligners[p].take(sums[p]);
    }
  }
  std::vector<RegistrationBatchOutcome> outcomes;
  outcomes.reserve(pairs.size());
  for (const RegistrationLm& aligner : aligners) outcomes.push_back(aligner.outcome());
  return outcomes;
}

}  // namespace backend
}  // namespace covox

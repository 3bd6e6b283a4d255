#pragma once
// The device side of the pose graph's registration terms for one solve: every buffer is
// allocated (and the points of all terms concatenated) once in the constructor; evaluate() and
// cost() then run a fixed sequence of launches per LM iterate.
#include <algorithm>
#include <map>
#include <vector>

#include "covoxslam/backend/registration_terms.h"
#include "covoxslam/backend/internal/registration_terms_ops.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/memory.h"

namespace covox {
namespace backend {

template <class Backend>
class RegistrationTermsWorkspace {
 public:
  RegistrationTermsWorkspace(const std::vector<RegistrationTerm>& terms, const Stream& stream)
      : stream_(stream) {
    const Device device = Backend::kDevice;
    term_count_ = static_cast<int64_t>(terms.size());
    // One lookup per distinct map: a kernel reaches every submap's field through this array.
    std::map<const map::TsdfMap*, int32_t> field_of_map;
    std::vector<RegistrationDistanceLookup> fields;
    std::vector<RegistrationTermView> views;
    std::vector<int64_t> point_offsets{0}, chunk_offsets{0}, term_chunk_offsets{0};
    for (const RegistrationTerm& term : terms) {
      auto found = field_of_map.find(term.map_j);
      if (found == field_of_map.end()) {
        found = field_of_map.emplace(term.map_j, static_cast<int32_t>(fields.size())).first;
        fields.push_back(make_registration_lookup(*term.map_j, term.residual));
      }
      RegistrationTermView view;
      view.vertex_i = term.vertex_i;
      view.vertex_j = term.vertex_j;
      view.field = found->second;
      view.tsdf_target = registration_uses_tsdf_target(term.residual) ? 1 : 0;
      view.tsdf_band_m = view.tsdf_target ? term.residual.tsdf_band_m : 0.0f;
      view.min_tsdf_weight = term.residual.min_tsdf_weight;
      view.robust = RobustLossParams{term.residual.loss, term.residual.loss_scale};
      view.inverse_sigma = 1.0 / term.residual_sigma;
      views.push_back(view);
      const int64_t n = static_cast<int64_t>(term.points_i->points.size());
      for (int64_t begin = 0; begin < n; begin += kRegistrationChunkPoints) {
        chunk_offsets.push_back(point_offsets.back() +
                                std::min(n, begin + kRegistrationChunkPoints));
      }
      term_chunk_offsets.push_back(static_cast<int64_t>(chunk_offsets.size()) - 1);
      point_offsets.push_back(point_offsets.back() + n);
    }
    point_count_ = point_offsets.back();
    chunk_count_ = static_cast<int64_t>(chunk_offsets.size()) - 1;
    fields_ = Buffer<RegistrationDistanceLookup>::from_host(device, fields, stream);
    terms_ = Buffer<RegistrationTermView>::from_host(device, views, stream);
    chunk_offsets_ = Buffer<int64_t>::from_host(device, chunk_offsets, stream);
    term_chunk_offsets_ = Buffer<int64_t>::from_host(device, term_chunk_offsets, stream);
    geometry_ = Buffer<RegistrationPairGeometry>(device, terms.size());
    points_ = Buffer<RegistrationPoint>(device, static_cast<size_t>(point_count_));
    std::vector<int32_t> point_term(static_cast<size_t>(point_count_));
    for (int64_t t = 0; t < term_count_; ++t) {
      std::fill(point_term.begin() + point_offsets[t], point_term.begin() + point_offsets[t + 1],
                static_cast<int32_t>(t));
      const auto& source = terms[t].points_i->points;
      if (source.size() > 0) {
        copy_bytes(points_.data() + point_offsets[t], device, source.data(), source.device(),
                   source.size_bytes(), stream);
      }
    }
    point_term_ = Buffer<int32_t>::from_host(device, point_term, stream);
    point_terms_ = Buffer<RegistrationPointTerm>(device, static_cast<size_t>(point_count_));
    point_costs_ = Buffer<double>(device, static_cast<size_t>(point_count_));
    chunk_sums_ =
        Buffer<double>(device, static_cast<size_t>(chunk_count_) * kRegistrationSumStride);
    term_sums_ = Buffer<double>(device, static_cast<size_t>(term_count_) * kRegistrationSumStride);
    stream.synchronize();
  }

  int64_t term_count() const { return term_count_; }
  int64_t point_count() const { return point_count_; }
  // kRegistrationSumStride doubles per term (registration_terms_ops.h), valid after evaluate().
  const double* term_sums() const { return term_sums_.data(); }

  // Residuals, Jacobians and per-term sums at `poses`; returns the terms' cost.
  double evaluate(const Pose4Dof* poses) {
    if (term_count_ == 0) return 0.0;
    const Backend b{};
    registration_terms_geometry(b, stream_, terms_.data(), term_count_, poses, geometry_.data());
    registration_terms_evaluate(b, stream_, points_.data(), point_term_.data(), point_count_,
                                terms_.data(), fields_.data(), geometry_.data(),
                                point_terms_.data(), point_costs_.data());
    registration_terms_reduce_chunks(b, stream_, point_terms_.data(), chunk_offsets_.data(),
                                     chunk_count_, chunk_sums_.data());
    registration_terms_reduce_terms(b, stream_, chunk_sums_.data(), term_chunk_offsets_.data(),
                                    term_count_, term_sums_.data());
    return sum_costs();
  }

  // The terms' cost only (trial steps).
  double cost(const Pose4Dof* poses) {
    if (term_count_ == 0) return 0.0;
    const Backend b{};
    registration_terms_geometry(b, stream_, terms_.data(), term_count_, poses, geometry_.data());
    registration_terms_evaluate(b, stream_, points_.data(), point_term_.data(), point_count_,
                                terms_.data(), fields_.data(), geometry_.data(),
                                static_cast<RegistrationPointTerm*>(nullptr), point_costs_.data());
    return sum_costs();
  }

  // Points inside their field at the last evaluate() (read back: diagnostics only).
  int64_t used_points() const {
    if (term_count_ == 0) return 0;
    const std::vector<double> sums = term_sums_.to_host(stream_);
    double used = 0.0;
    for (int64_t t = 0; t < term_count_; ++t)
      used += sums[t * kRegistrationSumStride + kRegistrationUsedOffset];
    return static_cast<int64_t>(used);
  }

 private:
  double sum_costs() {
    return reduce(Backend{}, stream_, point_costs_.data(), point_count_, 0.0,
                  thrust::plus<double>());
  }

  const Stream& stream_;
  int64_t term_count_ = 0, point_count_ = 0, chunk_count_ = 0;
  Buffer<RegistrationDistanceLookup> fields_;
  Buffer<RegistrationTermView> terms_;
  Buffer<int64_t> chunk_offsets_, term_chunk_offsets_;
  Buffer<RegistrationPairGeometry> geometry_;
  Buffer<RegistrationPoint> points_;
  Buffer<int32_t> point_term_;
  Buffer<RegistrationPointTerm> point_terms_;
  Buffer<double> point_costs_, chunk_sums_, term_sums_;
};

}  // namespace backend
}  // namespace covox

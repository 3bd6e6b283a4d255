#include "covoxslam/pipeline/place_recognition.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/pipeline/internal/place_descriptor.h"
#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

namespace {

constexpr double kPi = 3.14159265358979323846;

void require(bool condition, const std::string& message) {
  if (!condition) throw Error("SLAM configuration: place_recognition." + message);
}

double wrap_angle(double angle_rad) {
  const double wrapped = std::remainder(angle_rad, 2.0 * kPi);
  return wrapped <= -kPi ? wrapped + 2.0 * kPi : wrapped;
}

}  // namespace

void validate(const PlaceRecognitionConfig& config) {
  require(config.rings >= 1 && config.rings <= 200, "rings must be in [1, 200]");
  require(config.sectors >= 4 && config.sectors <= 720, "sectors must be in [4, 720]");
  require(std::isfinite(config.max_radius_m) && config.max_radius_m > 0.0,
          "max_radius_m must be finite and > 0");
  require(config.candidates >= 1, "candidates must be >= 1");
  require(std::isfinite(config.anchor_spacing_m) && config.anchor_spacing_m >= 0.0,
          "anchor_spacing_m must be finite and >= 0 (0: the origin only)");
  require(config.exclude_recent_submaps >= 0, "exclude_recent_submaps must be >= 0");
  require(std::isfinite(config.max_descriptor_distance) && config.max_descriptor_distance >= 0.0 &&
              config.max_descriptor_distance <= 1.0,
          "max_descriptor_distance must be in [0, 1]");
  require(std::isfinite(config.translation_search_m) && config.translation_search_m >= 0.0,
          "translation_search_m must be finite and >= 0");
  require(std::isfinite(config.max_residual_rms_vox) && config.max_residual_rms_vox > 0.0,
          "max_residual_rms_vox must be finite and > 0");
  require(std::isfinite(config.min_overlap_score) && config.min_overlap_score >= 0.0 &&
              config.min_overlap_score <= 1.0,
          "min_overlap_score must be in [0, 1]");
  require(std::isfinite(config.odometry_drift_m_per_m) && config.odometry_drift_m_per_m >= 0.0,
          "odometry_drift_m_per_m must be finite and >= 0");
  require(std::isfinite(config.odometry_drift_deg_per_m) && config.odometry_drift_deg_per_m >= 0.0,
          "odometry_drift_deg_per_m must be finite and >= 0");
  require(config.confirm_window_submaps >= 1, "confirm_window_submaps must be >= 1");
  require(std::isfinite(config.confirm_tolerance_m) && config.confirm_tolerance_m > 0.0,
          "confirm_tolerance_m must be finite and > 0");
  require(std::isfinite(config.confirm_tolerance_deg) && config.confirm_tolerance_deg > 0.0,
          "confirm_tolerance_deg must be finite and > 0");
  require(std::isfinite(config.max_odometry_mahalanobis_sq) &&
              config.max_odometry_mahalanobis_sq >= 0.0,
          "max_odometry_mahalanobis_sq must be finite and >= 0 (0: off)");
}

std::vector<SurfaceColumn> surface_columns(const map::TsdfMap& map, double surface_band_m,
                                           const Stream& stream) {
  // The kernel only reads the map; the view is non-const because kernels share one view type.
  auto& mutable_map = const_cast<map::TsdfMap&>(map);
  Buffer<Index3D> block_indices(map.device());
  Buffer<uint32_t> block_slots(map.device());
  map.blocks().export_entries(&block_indices, &block_slots);
  Buffer<uint64_t> keys(map.device());
  Buffer<uint64_t> spans(map.device());
  const int64_t count = dispatch(map.device(), [&](auto backend) {
    return place_surface_columns(backend, mutable_map.tsdf().view(), block_indices.data(),
                                 block_slots.data(), static_cast<int64_t>(block_indices.size()),
                                 map.voxels_per_side(), static_cast<float>(surface_band_m), &keys,
                                 &spans, stream);
  });
  std::vector<SurfaceColumn> columns(static_cast<size_t>(count));
  if (count == 0) return columns;
  const std::vector<uint64_t> host_keys = keys.to_host(stream);
  const std::vector<uint64_t> host_spans = spans.to_host(stream);
  const double voxel_m = map.voxel_size_m();
  for (int64_t i = 0; i < count; ++i) {
    int32_t x = 0, y = 0, top = 0, bottom = 0;
    place_column_of_key(host_keys[i], &x, &y);
    place_unpack_span(host_spans[i], &top, &bottom);
    SurfaceColumn& column = columns[static_cast<size_t>(i)];
    column.x_m = (x + 0.5) * voxel_m;
    column.y_m = (y + 0.5) * voxel_m;
    column.bottom_m = (bottom + 0.5) * voxel_m;
    column.top_m = (top + 0.5) * voxel_m;
  }
  return columns;
}

namespace {

// A cell whose surfaces span less than this vertically is ground (or a low kerb): every submap
// has it around its origin, so it would make any two submaps look alike.
constexpr double kMinStructureHeightM = 0.5;

// Lowest bottom and highest top of the columns in each cell, then the extent per cell.
struct CellSpans {
  std::vector<double> bottom, top;
  explicit CellSpans(size_t cells) : bottom(cells, 0.0), top(cells, 0.0), used(cells, false) {}
  std::vector<bool> used;
  void add(size_t cell, const SurfaceColumn& column) {
    bottom[cell] = used[cell] ? std::min(bottom[cell], column.bottom_m) : column.bottom_m;
    top[cell] = used[cell] ? std::max(top[cell], column.top_m) : column.top_m;
    used[cell] = true;
  }
  // The extents of the cells with structure; the others (ground, nothing) are 0.
  std::vector<float> extents() const {
    std::vector<float> result(bottom.size(), 0.0f);
    for (size_t c = 0; c < result.size(); ++c) {
      const double extent_m = top[c] - bottom[c];
      if (used[c] && extent_m >= kMinStructureHeightM) result[c] = static_cast<float>(extent_m);
    }
    return result;
  }
};

}  // namespace

PlaceDescriptor place_descriptor(const std::vector<SurfaceColumn>& columns,
                                 const PlaceRecognitionConfig& config,
                                 const Eigen::Vector2d& centre_m) {
  PlaceDescriptor d;
  d.rings = config.rings;
  d.sectors = config.sectors;
  d.max_radius_m = config.max_radius_m;
  const double ring_m = config.max_radius_m / config.rings;
  const int side = 2 * config.rings;
  CellSpans polar(static_cast<size_t>(config.rings) * config.sectors);
  CellSpans bird_eye(static_cast<size_t>(side) * side);
  for (const SurfaceColumn& column : columns) {
    const double x_m = column.x_m - centre_m.x(), y_m = column.y_m - centre_m.y();
    const double r = std::hypot(x_m, y_m);
    if (!(r < config.max_radius_m)) continue;
    const int ring = std::min(static_cast<int>(r / ring_m), config.rings - 1);
    const double turn = (std::atan2(y_m, x_m) + kPi) / (2.0 * kPi);
    const int sector = std::min(static_cast<int>(turn * config.sectors), config.sectors - 1);
    polar.add(static_cast<size_t>(ring) * config.sectors + sector, column);
    const int bx =
        std::clamp(static_cast<int>(std::floor(x_m / ring_m)) + config.rings, 0, side - 1);
    const int by =
        std::clamp(static_cast<int>(std::floor(y_m / ring_m)) + config.rings, 0, side - 1);
    bird_eye.add(static_cast<size_t>(by) * side + bx, column);
    ++d.columns;
  }
  d.polar = polar.extents();
  d.bird_eye = bird_eye.extents();
  d.ring_key.assign(static_cast<size_t>(config.rings), 0.0f);
  for (int ring = 0; ring < config.rings; ++ring) {
    double sum = 0.0;
    for (int s = 0; s < config.sectors; ++s)
      sum += d.polar[static_cast<size_t>(ring) * d.sectors + s];
    d.ring_key[static_cast<size_t>(ring)] = static_cast<float>(sum / config.sectors);
  }
  return d;
}

PlaceDescriptor place_descriptor(const map::TsdfMap& map, const PlaceRecognitionConfig& config,
                                 const Stream& stream) {
  return place_descriptor(surface_columns(map, map.voxel_size_m(), stream), config);
}

std::vector<Eigen::Vector2d> path_anchors(const std::vector<Eigen::Vector2d>& path_m,
                                          double spacing_m) {
  if (path_m.empty() || !(spacing_m > 0.0)) return {Eigen::Vector2d::Zero()};
  std::vector<Eigen::Vector2d> anchors{path_m.front()};
  double since_m = 0.0;
  for (size_t k = 1; k < path_m.size(); ++k) {
    since_m += (path_m[k] - path_m[k - 1]).norm();
    if (since_m >= spacing_m) {
      anchors.push_back(path_m[k]);
      since_m = 0.0;
    }
  }
  if (anchors.size() <= static_cast<size_t>(kMaxPathAnchors)) return anchors;
  std::vector<Eigen::Vector2d> thinned;
  for (int k = 0; k < kMaxPathAnchors; ++k) {
    thinned.push_back(anchors[k * (anchors.size() - 1) / (kMaxPathAnchors - 1)]);
  }
  return thinned;
}

DescriptorMatch match_descriptors(const PlaceDescriptor& moving, const PlaceDescriptor& fixed) {
  if (moving.rings != fixed.rings || moving.sectors != fixed.sectors) {
    throw Error("place recognition: descriptors of different grids");
  }
  const int rings = moving.rings, sectors = moving.sectors;
  // Per sector column: its norm, so a shift costs one dot product per column pair.
  auto norms = [&](const PlaceDescriptor& d) {
    std::vector<double> n(static_cast<size_t>(sectors), 0.0);
    for (int s = 0; s < sectors; ++s) {
      double sum = 0.0;
      for (int r = 0; r < rings; ++r) {
        const double v = d.polar[static_cast<size_t>(r) * sectors + s];
        sum += v * v;
      }
      n[static_cast<size_t>(s)] = std::sqrt(sum);
    }
    return n;
  };
  const std::vector<double> norm_m = norms(moving), norm_f = norms(fixed);
  DescriptorMatch best;
  for (int shift = 0; shift < sectors; ++shift) {
    double similarity = 0.0;
    int shared = 0;
    for (int s = 0; s < sectors; ++s) {
      const int t = (s + shift) % sectors;
      const bool has_m = norm_m[static_cast<size_t>(s)] > 0.0;
      const bool has_f = norm_f[static_cast<size_t>(t)] > 0.0;
      if (has_m || has_f) ++shared;  // structure on one side only: similarity 0
      if (!has_m || !has_f) continue;
      double dot = 0.0;
      for (int r = 0; r < rings; ++r) {
        dot += static_cast<double>(moving.polar[static_cast<size_t>(r) * sectors + s]) *
               fixed.polar[static_cast<size_t>(r) * sectors + t];
      }
      similarity += dot / (norm_m[static_cast<size_t>(s)] * norm_f[static_cast<size_t>(t)]);
    }
    if (shared == 0) continue;
    const double distance = 1.0 - similarity / shared;
    if (distance < best.distance) {
      best.distance = distance;
      best.shift = shift;
    }
  }
  best.yaw_rad = wrap_angle(2.0 * kPi * best.shift / sectors);
  return best;
}

namespace {

struct BirdEyeCell {
  double x_m, y_m;
  float value;
};

// The occupied cells of `moving`'s image, centres in its frame.
std::vector<BirdEyeCell> occupied_cells(const PlaceDescriptor& d, double* total) {
  const int side = 2 * d.rings;
  const double cell_m = d.max_radius_m / d.rings;
  std::vector<BirdEyeCell> cells;
  *total = 0.0;
  for (int by = 0; by < side; ++by) {
    for (int bx = 0; bx < side; ++bx) {
      const float v = d.bird_eye[static_cast<size_t>(by) * side + bx];
      if (!(v > 0.0f)) continue;
      cells.push_back(BirdEyeCell{(bx - d.rings + 0.5) * cell_m, (by - d.rings + 0.5) * cell_m, v});
      *total += v;
    }
  }
  return cells;
}

// The moving image turned by `yaw` about its origin onto the fixed image's grid: each occupied
// cell's centre lands in one cell, and cells landing together add up, so an overlap with it
// never counts a fixed cell twice.
struct TurnedImage {
  std::vector<int32_t> bx, by;
  std::vector<float> value;
};

TurnedImage turned_image(const std::vector<BirdEyeCell>& cells, const PlaceDescriptor& fixed,
                         double yaw, std::vector<float>* scratch) {
  const int side = 2 * fixed.rings;
  const double cell_m = fixed.max_radius_m / fixed.rings;
  const double c = std::cos(yaw), s = std::sin(yaw);
  // Turned cells may leave the square by up to its half diagonal: a grid of twice the side.
  const int margin = side / 2, wide = 2 * side;
  scratch->assign(static_cast<size_t>(wide) * wide, 0.0f);
  std::vector<int32_t> touched;
  for (const BirdEyeCell& cell : cells) {
    const double x = c * cell.x_m - s * cell.y_m;
    const double y = s * cell.x_m + c * cell.y_m;
    const int bx = static_cast<int>(std::floor(x / cell_m)) + fixed.rings + margin;
    const int by = static_cast<int>(std::floor(y / cell_m)) + fixed.rings + margin;
    if (bx < 0 || by < 0 || bx >= wide || by >= wide) continue;
    float& slot = (*scratch)[static_cast<size_t>(by) * wide + bx];
    if (slot == 0.0f) touched.push_back(by * wide + bx);
    slot += cell.value;
  }
  TurnedImage image;
  for (int32_t k : touched) {
    image.bx.push_back(k % wide - margin);
    image.by.push_back(k / wide - margin);
    image.value.push_back((*scratch)[static_cast<size_t>(k)]);
  }
  return image;
}

// Sum of min(turned moving, fixed) with the turned image moved by whole cells (ix, iy).
double overlap_at(const TurnedImage& turned, const PlaceDescriptor& fixed, int ix, int iy) {
  const int side = 2 * fixed.rings;
  double sum = 0.0;
  for (size_t k = 0; k < turned.value.size(); ++k) {
    const int bx = turned.bx[k] + ix, by = turned.by[k] + iy;
    if (bx < 0 || by < 0 || bx >= side || by >= side) continue;
    sum += std::min(turned.value[k], fixed.bird_eye[static_cast<size_t>(by) * side + bx]);
  }
  return sum;
}

}  // namespace

BirdEyeMatch match_bird_eye(const PlaceDescriptor& moving, const PlaceDescriptor& fixed,
                            double yaw_rad, const PlaceRecognitionConfig& config) {
  BirdEyeMatch best;
  double moving_total = 0.0, fixed_total = 0.0;
  const std::vector<BirdEyeCell> cells = occupied_cells(moving, &moving_total);
  occupied_cells(fixed, &fixed_total);
  const double normaliser = std::min(moving_total, fixed_total);
  if (!(normaliser > 0.0)) return best;
  const double cell_m = fixed.max_radius_m / fixed.rings;
  const int steps = static_cast<int>(std::floor(config.translation_search_m / cell_m));
  // Every sector's yaw (the polar shift is unreliable once the origins are metres apart), then
  // half a sector either side of the best.
  const double sector_rad = 2.0 * kPi / fixed.sectors;
  double best_sum = -1.0;
  std::vector<float> scratch;
  auto search = [&](double yaw) {
    const TurnedImage turned = turned_image(cells, fixed, yaw, &scratch);
    for (int iy = -steps; iy <= steps; ++iy) {
      for (int ix = -steps; ix <= steps; ++ix) {
        const double sum = overlap_at(turned, fixed, ix, iy);
        if (sum > best_sum) {
          best_sum = sum;
          best.T_fixed_moving.x = ix * cell_m;
          best.T_fixed_moving.y = iy * cell_m;
          best.T_fixed_moving.yaw = yaw;
        }
      }
    }
  };
  for (int k = 0; k < fixed.sectors; ++k) search(wrap_angle(yaw_rad + k * sector_rad));
  const double coarse_yaw = best.T_fixed_moving.yaw;
  search(wrap_angle(coarse_yaw - 0.5 * sector_rad));
  search(wrap_angle(coarse_yaw + 0.5 * sector_rad));
  best.score = std::max(best_sum, 0.0) / normaliser;
  return best;
}

void PlaceRecognitionCounts::add(const PlaceRecognitionCounts& other) {
  queries += other.queries;
  candidates += other.candidates;
  skipped_linked += other.skipped_linked;
  rejected_descriptor += other.rejected_descriptor;
  rejected_overlap += other.rejected_overlap;
  verified += other.verified;
  unconfirmed += other.unconfirmed;
  accepted += other.accepted;
  registration.add(other.registration);
}

PlaceRecognizer::PlaceRecognizer(const PlaceRecognitionConfig& config) : config_(config) {
  validate(config_);
}

void PlaceRecognizer::clear() {
  descriptors_.clear();
  index_.clear();
}

SubmapRegistrationConfig PlaceRecognizer::closure_checks(
    const SubmapRegistrationConfig& registration) const {
  // The registration's tests, at least as strict as max_residual_rms_vox and
  // max_odometry_mahalanobis_sq: a candidate's alignment starts from a guess, not from a pose the
  // odometry vouches for.
  SubmapRegistrationConfig checked = registration;
  double& max_rms_vox = checked.acceptance.max_residual_rms_vox;
  if (!(max_rms_vox > 0.0) || max_rms_vox > config_.max_residual_rms_vox) {
    max_rms_vox = config_.max_residual_rms_vox;
  }
  double& max_sq = checked.verification.max_mahalanobis_sq;
  if (config_.max_odometry_mahalanobis_sq > 0.0 &&
      (!(max_sq > 0.0) || max_sq > config_.max_odometry_mahalanobis_sq)) {
    max_sq = config_.max_odometry_mahalanobis_sq;
  }
  return checked;
}

RegistrationOdometry PlaceRecognizer::with_closure_drift(RegistrationOdometry odometry) const {
  odometry.drift_m_per_m = std::max(odometry.drift_m_per_m, config_.odometry_drift_m_per_m);
  odometry.drift_rad_per_m =
      std::max(odometry.drift_rad_per_m, config_.odometry_drift_deg_per_m * kPi / 180.0);
  return odometry;
}

RegistrationPartner PlaceRecognizer::with_closure_drift(RegistrationPartner partner) const {
  partner.odometry = with_closure_drift(partner.odometry);
  return partner;
}

const PlaceRecognizer::Entry* PlaceRecognizer::find(int64_t id) const {
  const auto it = std::lower_bound(descriptors_.begin(), descriptors_.end(), id,
                                   [](const Entry& e, int64_t value) { return e.id < value; });
  return it != descriptors_.end() && it->id == id ? &*it : nullptr;
}

std::vector<PlaceRecognizer::AnchorPair> PlaceRecognizer::nearest_submaps(const Entry& entry,
                                                                          int64_t max_id) const {
  struct Scored {
    double distance_sq;
    AnchorPair pair;
  };
  std::vector<Scored> best;  // one per earlier submap
  // Neighbouring anchors of one submap look alike: more keys than submaps are asked for.
  const size_t keys_wanted = static_cast<size_t>(config_.candidates) * 4;
  const int64_t max_key = (max_id + 1) * kMaxPathAnchors - 1;
  for (size_t own = 0; own < entry.anchors.size(); ++own) {
    const std::vector<float>& key = entry.anchors[own].ring_key;
    if (entry.anchors[own].empty()) continue;
    for (int64_t found : index_.nearest(key, keys_wanted, max_key)) {
      const int64_t id = found / kMaxPathAnchors;
      const size_t their = static_cast<size_t>(found % kMaxPathAnchors);
      const Entry* other = find(id);
      if (!other || their >= other->anchors.size()) continue;
      double distance_sq = 0.0;
      for (size_t r = 0; r < key.size(); ++r) {
        const double d = static_cast<double>(key[r]) - other->anchors[their].ring_key[r];
        distance_sq += d * d;
      }
      auto it =
          std::find_if(best.begin(), best.end(), [&](const Scored& s) { return s.pair.id == id; });
      if (it == best.end()) {
        best.push_back(Scored{distance_sq, AnchorPair{id, own, their}});
      } else if (distance_sq < it->distance_sq) {
        *it = Scored{distance_sq, AnchorPair{id, own, their}};
      }
    }
  }
  std::sort(best.begin(), best.end(), [](const Scored& a, const Scored& b) {
    return a.distance_sq < b.distance_sq ||
           (a.distance_sq == b.distance_sq && a.pair.id < b.pair.id);
  });
  if (best.size() > static_cast<size_t>(config_.candidates)) best.resize(config_.candidates);
  std::vector<AnchorPair> pairs;
  for (const Scored& scored : best) pairs.push_back(scored.pair);
  return pairs;
}

std::vector<PlaceCandidate> PlaceRecognizer::search(int64_t id, const map::TsdfMap& map,
                                                    const std::vector<Eigen::Vector2d>& path_m,
                                                    const std::vector<int64_t>& earlier_ids,
                                                    const std::vector<int64_t>& linked,
                                                    const Stream& stream,
                                                    PlaceRecognitionCounts* counts) {
  std::vector<PlaceCandidate> found;
  if (!config_.enabled) return found;
  ++counts->queries;
  const std::vector<SurfaceColumn> columns = surface_columns(map, map.voxel_size_m(), stream);
  Entry entry{id, place_descriptor(columns, config_), {}};
  for (const Eigen::Vector2d& anchor : path_anchors(path_m, config_.anchor_spacing_m)) {
    PlaceDescriptor d = place_descriptor(columns, config_, anchor);
    d.bird_eye = std::vector<float>();
    entry.anchors.push_back(std::move(d));
  }
  const int64_t max_id = id - 1 - config_.exclude_recent_submaps;
  for (const AnchorPair& pair : nearest_submaps(entry, max_id)) {
    const int64_t candidate = pair.id;
    const Entry* other = find(candidate);
    if (std::find(earlier_ids.begin(), earlier_ids.end(), candidate) == earlier_ids.end()) continue;
    ++counts->candidates;
    if (std::find(linked.begin(), linked.end(), candidate) != linked.end()) {
      ++counts->skipped_linked;
      continue;
    }
    // The anchors' frames share their submaps' axes: the polar shift is a yaw of the submaps.
    const DescriptorMatch match =
        match_descriptors(entry.anchors[pair.own], other->anchors[pair.their]);
    log_message(LogLevel::kDebug, "SLAM place recognition: submap ", candidate, " -> ", id,
                ": descriptor distance ", match.distance, " yaw ", match.yaw_rad, " anchors ",
                pair.own, " ", pair.their);
    if (match.distance > config_.max_descriptor_distance) {
      ++counts->rejected_descriptor;
      continue;
    }
    const BirdEyeMatch overlap =
        match_bird_eye(entry.descriptor, other->descriptor, match.yaw_rad, config_);
    log_message(LogLevel::kDebug, "SLAM place recognition: submap ", candidate, " -> ", id,
                ": overlap ", overlap.score, " at (", overlap.T_fixed_moving.x, ", ",
                overlap.T_fixed_moving.y, ", ", overlap.T_fixed_moving.yaw, ")");
    if (overlap.score < config_.min_overlap_score) {
      ++counts->rejected_overlap;
      continue;
    }
    found.push_back(
        PlaceCandidate{candidate, overlap.T_fixed_moving, match.distance, overlap.score});
  }
  for (size_t a = 0; a < entry.anchors.size(); ++a) {
    if (!entry.anchors[a].empty()) {
      index_.add(id * kMaxPathAnchors + static_cast<int64_t>(a), entry.anchors[a].ring_key);
    }
  }
  descriptors_.push_back(std::move(entry));
  return found;
}

std::vector<VerifiedClosure> PlaceRecognizer::verify(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<PlaceCandidate>& candidates,
    const std::vector<RegistrationPartner>& earlier, const SubmapRegistrationConfig& registration,
    const Stream& stream, WallMapCache* own_walls, const RegistrationOdometry& odometry,
    PlaceRecognitionCounts* counts) const {
  std::vector<VerifiedClosure> verified;
  const SubmapRegistrationConfig checked = closure_checks(registration);
  const RegistrationOdometry closure_odometry = with_closure_drift(odometry);
  for (const PlaceCandidate& candidate : candidates) {
    const auto partner =
        std::find_if(earlier.begin(), earlier.end(),
                     [&](const RegistrationPartner& p) { return p.id == candidate.id; });
    if (partner == earlier.end()) {
      throw Error("place recognition: candidate submap " + std::to_string(candidate.id) +
                  " is not among the earlier submaps given to verify()");
    }
    // The height offset is the one thing the descriptors do not give: the current estimate's.
    backend::Pose4Dof guess = candidate.T_fixed_moving;
    guess.z = relative_pose_4dof(partner->pose, pose).z;
    ++counts->verified;
    VerifiedClosure closure;
    if (registration_constraint_from_guess(id, map, points, pose, with_closure_drift(*partner),
                                           guess, checked, stream, &counts->registration, own_walls,
                                           closure_odometry, &closure.constraint)) {
      closure.constraint.from_place_recognition = true;
      closure.earlier_odometry = partner->odometry;
      closure.new_odometry = odometry;
      verified.push_back(closure);
    }
  }
  return verified;
}

double closure_disagreement(const VerifiedClosure& a, const VerifiedClosure& b,
                            const PlaceRecognitionConfig& config) {
  if (!a.earlier_odometry.known || !a.new_odometry.known || !b.earlier_odometry.known ||
      !b.new_odometry.known) {
    return std::numeric_limits<double>::infinity();  // a loaded submap: no odometry to close with
  }
  // The pose of b's new submap in the frame of a's earlier one, both ways round the cycle: a's
  // closure then the odometry between the new submaps, or the odometry between the earlier
  // submaps then b's closure.
  const backend::Pose4Dof via_a = compose(
      a.constraint.measurement, relative_pose_4dof(a.new_odometry.pose, b.new_odometry.pose));
  const backend::Pose4Dof via_b =
      compose(relative_pose_4dof(a.earlier_odometry.pose, b.earlier_odometry.pose),
              b.constraint.measurement);
  // Two closures far apart on the earlier pass say nothing about each other (the odometry's
  // drift between them may be anything the tolerance allows): they never agree.
  const int64_t window = config.confirm_window_submaps;
  if (std::abs(a.constraint.from_submap - b.constraint.from_submap) > window ||
      std::abs(a.constraint.to_submap - b.constraint.to_submap) > window) {
    return std::numeric_limits<double>::infinity();
  }
  const double path_m = std::abs(a.new_odometry.path_m - b.new_odometry.path_m) +
                        std::abs(a.earlier_odometry.path_m - b.earlier_odometry.path_m);
  const double tolerance_m = config.confirm_tolerance_m + config.odometry_drift_m_per_m * path_m;
  const double tolerance_rad =
      (config.confirm_tolerance_deg + config.odometry_drift_deg_per_m * path_m) * kPi / 180.0;
  const double error_m = std::sqrt((via_a.x - via_b.x) * (via_a.x - via_b.x) +
                                   (via_a.y - via_b.y) * (via_a.y - via_b.y) +
                                   (via_a.z - via_b.z) * (via_a.z - via_b.z));
  const double error_rad = std::abs(wrap_angle(via_a.yaw - via_b.yaw));
  const double ratio = std::max(error_m / tolerance_m, error_rad / tolerance_rad);
  return ratio * ratio;
}

std::vector<SubmapConstraint> PlaceRecognizer::confirm(int64_t id,
                                                       const std::vector<VerifiedClosure>& verified,
                                                       PlaceRecognitionCounts* counts) {
  // Closures of submaps that left the window can no longer be confirmed by a new one.
  const int64_t oldest = id - config_.confirm_window_submaps;
  for (const Waiting& w : waiting_) {
    if (!w.confirmed && w.closure.constraint.to_submap < oldest) ++counts->unconfirmed;
  }
  waiting_.erase(
      std::remove_if(waiting_.begin(), waiting_.end(),
                     [&](const Waiting& w) { return w.closure.constraint.to_submap < oldest; }),
      waiting_.end());
  std::vector<SubmapConstraint> confirmed;
  for (const VerifiedClosure& closure : verified) {
    bool agreed = false;
    for (Waiting& w : waiting_) {
      if (w.closure.constraint.to_submap == id) continue;  // another new submap's closure only
      if (closure_disagreement(w.closure, closure, config_) > 1.0) continue;
      agreed = true;
      if (!w.confirmed) {
        w.confirmed = true;
        confirmed.push_back(w.closure.constraint);
      }
    }
    waiting_.push_back(Waiting{closure, agreed});
    if (agreed) confirmed.push_back(closure.constraint);
  }
  counts->accepted += static_cast<int64_t>(confirmed.size());
  return confirmed;
}

std::vector<SubmapConstraint> PlaceRecognizer::propose(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<RegistrationPartner>& earlier,
    const std::vector<int64_t>& linked, const SubmapRegistrationConfig& registration,
    const Stream& stream, WallMapCache* own_walls, const RegistrationOdometry& odometry,
    PlaceRecognitionCounts* counts) {
  std::vector<int64_t> earlier_ids;
  for (const RegistrationPartner& partner : earlier) earlier_ids.push_back(partner.id);
  const std::vector<PlaceCandidate> candidates =
      search(id, map, {}, earlier_ids, linked, stream, counts);
  return confirm(id,
                 verify(id, map, points, pose, candidates, earlier, registration, stream, own_walls,
                        odometry, counts),
                 counts);
}

}  // namespace pipeline
}  // namespace covox

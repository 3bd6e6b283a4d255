#include "covoxslam/pipeline/place_recognition.h"

#include <algorithm>
#include <cmath>
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
                                 const PlaceRecognitionConfig& config) {
  PlaceDescriptor d;
  d.rings = config.rings;
  d.sectors = config.sectors;
  d.max_radius_m = config.max_radius_m;
  const double ring_m = config.max_radius_m / config.rings;
  const int side = 2 * config.rings;
  CellSpans polar(static_cast<size_t>(config.rings) * config.sectors);
  CellSpans bird_eye(static_cast<size_t>(side) * side);
  for (const SurfaceColumn& column : columns) {
    const double r = std::hypot(column.x_m, column.y_m);
    if (!(r < config.max_radius_m)) continue;
    const int ring = std::min(static_cast<int>(r / ring_m), config.rings - 1);
    const double turn = (std::atan2(column.y_m, column.x_m) + kPi) / (2.0 * kPi);
    const int sector = std::min(static_cast<int>(turn * config.sectors), config.sectors - 1);
    polar.add(static_cast<size_t>(ring) * config.sectors + sector, column);
    const int bx =
        std::clamp(static_cast<int>(std::floor(column.x_m / ring_m)) + config.rings, 0, side - 1);
    const int by =
        std::clamp(static_cast<int>(std::floor(column.y_m / ring_m)) + config.rings, 0, side - 1);
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

// Sum of min(moving, fixed) over the moving cells moved by (yaw, tx, ty) into fixed's image.
double overlap_at(const std::vector<BirdEyeCell>& cells, const PlaceDescriptor& fixed, double yaw,
                  double tx, double ty) {
  const int side = 2 * fixed.rings;
  const double cell_m = fixed.max_radius_m / fixed.rings;
  const double c = std::cos(yaw), s = std::sin(yaw);
  double sum = 0.0;
  for (const BirdEyeCell& cell : cells) {
    const double x = c * cell.x_m - s * cell.y_m + tx;
    const double y = s * cell.x_m + c * cell.y_m + ty;
    const int bx = static_cast<int>(std::floor(x / cell_m)) + fixed.rings;
    const int by = static_cast<int>(std::floor(y / cell_m)) + fixed.rings;
    if (bx < 0 || by < 0 || bx >= side || by >= side) continue;
    sum += std::min(cell.value, fixed.bird_eye[static_cast<size_t>(by) * side + bx]);
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
  auto search = [&](double yaw) {
    for (int iy = -steps; iy <= steps; ++iy) {
      for (int ix = -steps; ix <= steps; ++ix) {
        const double sum = overlap_at(cells, fixed, yaw, ix * cell_m, iy * cell_m);
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

std::vector<SubmapConstraint> PlaceRecognizer::propose(
    int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
    const backend::Pose4Dof& pose, const std::vector<RegistrationPartner>& earlier,
    const std::vector<int64_t>& linked, const SubmapRegistrationConfig& registration,
    const Stream& stream, WallMapCache* own_walls, const RegistrationOdometry& odometry,
    PlaceRecognitionCounts* counts) {
  std::vector<SubmapConstraint> constraints;
  if (!config_.enabled) return constraints;
  ++counts->queries;
  PlaceDescriptor descriptor = place_descriptor(map, config_, stream);
  const int64_t max_id = id - 1 - config_.exclude_recent_submaps;
  const std::vector<int64_t> nearest =
      descriptor.empty()
          ? std::vector<int64_t>()
          : index_.nearest(descriptor.ring_key, static_cast<size_t>(config_.candidates), max_id);
  SubmapRegistrationConfig checked = closure_checks(registration);
  const RegistrationOdometry closure_odometry = with_closure_drift(odometry);
  for (int64_t candidate : nearest) {
    const Entry* entry = find(candidate);
    const auto partner =
        std::find_if(earlier.begin(), earlier.end(),
                     [&](const RegistrationPartner& p) { return p.id == candidate; });
    if (!entry || partner == earlier.end()) continue;
    ++counts->candidates;
    if (std::find(linked.begin(), linked.end(), candidate) != linked.end()) {
      ++counts->skipped_linked;
      continue;
    }
    const DescriptorMatch match = match_descriptors(descriptor, entry->descriptor);
    log_message(LogLevel::kDebug, "SLAM place recognition: submap ", candidate, " -> ", id,
                ": descriptor distance ", match.distance, " yaw ", match.yaw_rad);
    if (match.distance > config_.max_descriptor_distance) {
      ++counts->rejected_descriptor;
      continue;
    }
    const BirdEyeMatch overlap =
        match_bird_eye(descriptor, entry->descriptor, match.yaw_rad, config_);
    log_message(LogLevel::kDebug, "SLAM place recognition: submap ", candidate, " -> ", id,
                ": overlap ", overlap.score, " at (", overlap.T_fixed_moving.x, ", ",
                overlap.T_fixed_moving.y, ", ", overlap.T_fixed_moving.yaw, ")");
    if (overlap.score < config_.min_overlap_score) {
      ++counts->rejected_overlap;
      continue;
    }
    // The height offset is the one thing the descriptors do not give: the current estimate's.
    backend::Pose4Dof guess = overlap.T_fixed_moving;
    guess.z = relative_pose_4dof(partner->pose, pose).z;
    ++counts->verified;
    SubmapConstraint constraint;
    if (registration_constraint_from_guess(id, map, points, pose, with_closure_drift(*partner),
                                           guess, checked, stream, &counts->registration, own_walls,
                                           closure_odometry, &constraint)) {
      ++counts->accepted;
      constraints.push_back(constraint);
    }
  }
  if (!descriptor.empty()) index_.add(id, descriptor.ring_key);
  descriptors_.push_back(Entry{id, std::move(descriptor)});
  return constraints;
}

}  // namespace pipeline
}  // namespace covox

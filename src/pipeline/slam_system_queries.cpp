// The ROS-facing queries of SlamSystem (the marked block in slam_system.h): per-submap meshes,
// ESDF slices at a world height, ESDF samples at world points and the 3-D ESDF near surfaces.
// Finished submaps are frozen, so their voxels can be read while backend_mutex_ keeps the graph's
// structure (and with it the submaps' lifetime) unchanged; state_mutex_ is held only to copy poses
// and pointers, so the frontend never waits for a slice.
#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <utility>

#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

namespace {

// The ESDF slice of one submap at world height `height_m`, moved into the world frame. Submap
// frames are gravity aligned (x, y, z, yaw), so a horizontal world plane is a horizontal plane of
// the submap at height_m - t_z.
std::vector<integrators::SlicePoint> world_slice_of(const map::TsdfMap& map,
                                                    const Eigen::Isometry3d& T_world_submap,
                                                    double height_m, const Stream& stream) {
  const float z_submap_m = static_cast<float>(height_m - T_world_submap.translation().z());
  std::vector<integrators::SlicePoint> slice = integrators::esdf_slice(map, z_submap_m, stream);
  const Eigen::Isometry3f T = T_world_submap.cast<float>();
  for (integrators::SlicePoint& point : slice) {
    const Eigen::Vector3f world =
        T * Eigen::Vector3f(point.position_m.x, point.position_m.y, point.position_m.z);
    point.position_m = Vec3f(world.x(), world.y(), static_cast<float>(height_m));
  }
  return slice;
}

// Keeps, per cell of a world grid of `cell_m`, the smallest distance of the points falling in
// it, reported at the cell centre: in x and y, and in z too when `bin_z` (else a point keeps its
// own height, as a slice's points share one). Overlapping submaps thus give one point per cell,
// the conservative one for planners.
class CellMinimum {
 public:
  CellMinimum(double cell_m, bool bin_z) : cell_m_(cell_m), bin_z_(bin_z) {}

  void add(const integrators::SlicePoint& point) {
    const int64_t i = cell_of(point.position_m.x), j = cell_of(point.position_m.y),
                  k = bin_z_ ? cell_of(point.position_m.z) : 0;
    // 21 bits per index (biased): +-10^6 cells, far beyond any map.
    const uint64_t key = (static_cast<uint64_t>(i + kBias) << 42) |
                         (static_cast<uint64_t>(j + kBias) << 21) |
                         static_cast<uint64_t>(k + kBias);
    auto it = cells_.find(key);
    if (it == cells_.end()) {
      integrators::SlicePoint centred = point;
      centred.position_m.x = centre_of(i);
      centred.position_m.y = centre_of(j);
      if (bin_z_) centred.position_m.z = centre_of(k);
      cells_.emplace(key, centred);
    } else if (point.distance_m < it->second.distance_m) {
      it->second.distance_m = point.distance_m;
    }
  }

  std::vector<integrators::SlicePoint> points() const {
    std::vector<integrators::SlicePoint> merged;
    merged.reserve(cells_.size());
    for (const auto& cell : cells_) merged.push_back(cell.second);
    return merged;
  }

 private:
  static constexpr int64_t kBias = int64_t(1) << 20;
  int64_t cell_of(float x) const { return static_cast<int64_t>(std::floor(x / cell_m_)); }
  float centre_of(int64_t i) const { return static_cast<float>((i + 0.5) * cell_m_); }

  double cell_m_;
  bool bin_z_;
  std::unordered_map<uint64_t, integrators::SlicePoint> cells_;
};

}  // namespace

bool SlamSystem::submap_mesh(int64_t id, map::Mesh* mesh_submap,
                             Eigen::Isometry3d* T_world_submap) const {
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    auto it = std::find_if(graph_submaps_.begin(), graph_submaps_.end(),
                           [id](const GraphSubmap& entry) { return entry.submap->id() == id; });
    if (it == graph_submaps_.end()) return false;
    *T_world_submap = it->submap->T_world_submap();
  }
  // The store holds the mesh under its own lock (decoded if the submap was compacted).
  return store_->mesh(id, mesh_submap);
}

void SlamSystem::visit_finished_submaps(
    const std::function<void(const map::TsdfMap&, const Eigen::Isometry3d&)>& visit) {
  std::lock_guard<std::mutex> structure_lock(backend_mutex_);
  std::vector<std::pair<Submap*, Eigen::Isometry3d>> submaps;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const GraphSubmap& entry : graph_submaps_) {
      if (entry.submap) submaps.emplace_back(entry.submap.get(), entry.submap->T_world_submap());
    }
  }
  for (const auto& [submap, T_world_submap] : submaps) {
    // A sweep: brought back for this visit only, it is the first to leave again below.
    acquire_locked(*submap, /*mark_used=*/false);
    enforce_budget_locked(submap->id());
    visit(submap->map(), T_world_submap);
  }
  enforce_budget_locked(-1);
}

std::vector<integrators::SlicePoint> SlamSystem::esdf_slice_world(double height_m) {
  CellMinimum cells(config_.map.voxel_size_m, /*bin_z=*/false);
  const Stream stream = Stream::create(config_.device);
  visit_finished_submaps([&](const map::TsdfMap& map, const Eigen::Isometry3d& T_world_submap) {
    for (const integrators::SlicePoint& point :
         world_slice_of(map, T_world_submap, height_m, stream))
      cells.add(point);
  });
  return cells.points();
}

std::vector<integrators::EsdfSample> SlamSystem::query_esdf_world(
    const std::vector<Vec3f>& points_world_m) {
  std::vector<integrators::EsdfSample> merged(points_world_m.size());
  if (points_world_m.empty()) return merged;
  std::vector<Vec3f> points_submap_m(points_world_m.size());
  visit_finished_submaps([&](const map::TsdfMap& map, const Eigen::Isometry3d& T_world_submap) {
    const Eigen::Isometry3f T_submap_world = T_world_submap.inverse().cast<float>();
    for (size_t i = 0; i < points_world_m.size(); ++i) {
      const Vec3f& p = points_world_m[i];
      const Eigen::Vector3f q = T_submap_world * Eigen::Vector3f(p.x, p.y, p.z);
      points_submap_m[i] = Vec3f(q.x(), q.y(), q.z());
    }
    const std::vector<integrators::EsdfSample> samples =
        integrators::query_esdf(map, points_submap_m);
    const Eigen::Matrix3f R_world_submap = T_world_submap.linear().cast<float>();
    for (size_t i = 0; i < samples.size(); ++i) {
      const integrators::EsdfSample& sample = samples[i];
      if (!sample.valid || (merged[i].valid && merged[i].distance_m <= sample.distance_m)) continue;
      const Eigen::Vector3f g =
          R_world_submap * Eigen::Vector3f(sample.gradient.x, sample.gradient.y, sample.gradient.z);
      merged[i].distance_m = sample.distance_m;
      merged[i].gradient = Vec3f(g.x(), g.y(), g.z());
      merged[i].valid = 1;
    }
  });
  return merged;
}

std::vector<integrators::SlicePoint> SlamSystem::esdf_voxels_world(double max_distance_m,
                                                                   size_t max_points,
                                                                   bool* truncated) {
  CellMinimum cells(config_.map.voxel_size_m, /*bin_z=*/true);
  const Stream stream = Stream::create(config_.device);
  visit_finished_submaps([&](const map::TsdfMap& map, const Eigen::Isometry3d& T_world_submap) {
    const Eigen::Isometry3f T = T_world_submap.cast<float>();
    for (integrators::SlicePoint point :
         integrators::esdf_voxels_within(map, static_cast<float>(max_distance_m), stream)) {
      const Eigen::Vector3f world =
          T * Eigen::Vector3f(point.position_m.x, point.position_m.y, point.position_m.z);
      point.position_m = Vec3f(world.x(), world.y(), world.z());
      cells.add(point);
    }
  });
  std::vector<integrators::SlicePoint> voxels = cells.points();
  *truncated = voxels.size() > max_points;
  if (*truncated) {
    std::nth_element(voxels.begin(), voxels.begin() + static_cast<std::ptrdiff_t>(max_points),
                     voxels.end(),
                     [](const integrators::SlicePoint& a, const integrators::SlicePoint& b) {
                       return a.distance_m < b.distance_m;
                     });
    voxels.resize(max_points);
  }
  return voxels;
}

std::vector<integrators::SlicePoint> SlamSystem::esdf_slice_newest_submap(double height_m,
                                                                          int64_t* submap_id) {
  std::lock_guard<std::mutex> structure_lock(backend_mutex_);
  Submap* newest = nullptr;
  Eigen::Isometry3d T_world_submap = Eigen::Isometry3d::Identity();
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const GraphSubmap& entry : graph_submaps_) {
      if (entry.submap && (!newest || entry.submap->id() > newest->id()))
        newest = entry.submap.get();
    }
    if (newest) T_world_submap = newest->T_world_submap();
  }
  *submap_id = newest ? newest->id() : -1;
  if (!newest) return {};
  acquire_locked(*newest);
  const Stream stream = Stream::create(config_.device);
  std::vector<integrators::SlicePoint> slice =
      world_slice_of(newest->map(), T_world_submap, height_m, stream);
  enforce_budget_locked(-1);
  return slice;
}

std::vector<integrators::SlicePoint> SlamSystem::esdf_slice_active_submap(double height_m,
                                                                          int64_t* submap_id) {
  *submap_id = -1;
  // The next copy, for the next call; an idle frontend takes it at once.
  active_copy_requested_.store(true);
  sensor_queue_.wake();
  std::shared_ptr<const ActiveSubmapCopy> copy;
  {
    std::lock_guard<std::mutex> lock(active_copy_mutex_);
    copy = active_copy_;
  }
  if (!copy || copy->generation != generation_.load()) return {};
  Eigen::Isometry3d T_world_submap;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    T_world_submap = correction_for_locked(copy->id) * copy->T_odom_submap;
  }
  // Only the blocks whose surfaces can be nearest to a voxel of the slice: sites further than
  // esdf_max_distance_m from its layer do not change its (clamped) distances. One voxel more
  // covers the layer's own thickness.
  const double z_submap_m = height_m - T_world_submap.translation().z();
  const double reach_m = config_.esdf.esdf_max_distance_m + config_.map.voxel_size_m;
  const double block_m =
      static_cast<double>(config_.map.voxel_size_m) * config_.map.voxels_per_side;
  std::vector<map::HostBlock> slab;
  for (const map::HostBlock& block : copy->blocks) {
    const double bottom_m = block.index.z * block_m;
    if (bottom_m <= z_submap_m + reach_m && bottom_m + block_m >= z_submap_m - reach_m) {
      map::HostBlock without_esdf;
      without_esdf.index = block.index;
      without_esdf.tsdf = block.tsdf;
      without_esdf.color = block.color;
      slab.push_back(std::move(without_esdf));
    }
  }
  *submap_id = copy->id;
  if (slab.empty()) return {};
  const Stream stream = Stream::create(config_.device);
  map::TsdfMap map(config_.device, config_.map);
  map.load_blocks(slab, stream);
  integrators::EsdfIntegrator(config_.esdf).update_all(map, stream);
  return world_slice_of(map, T_world_submap, height_m, stream);
}

}  // namespace pipeline
}  // namespace covox

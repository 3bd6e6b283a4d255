// The ROS-facing queries of SlamSystem (the marked block in slam_system.h): per-submap meshes and
// ESDF slices at a world height. Finished submaps are frozen, so their voxels can be read while
// backend_mutex_ keeps the graph's structure (and with it the submaps' lifetime) unchanged;
// state_mutex_ is held only to copy poses and pointers, so the frontend never waits for a slice.
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

std::vector<integrators::SlicePoint> SlamSystem::esdf_slice_world(double height_m) {
  std::lock_guard<std::mutex> structure_lock(backend_mutex_);
  std::vector<std::pair<Submap*, Eigen::Isometry3d>> submaps;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const GraphSubmap& entry : graph_submaps_) {
      if (entry.submap) submaps.emplace_back(entry.submap.get(), entry.submap->T_world_submap());
    }
  }
  const double cell_m = config_.map.voxel_size_m;
  // Cell key: the two grid indices packed into one 64-bit integer.
  auto key_of = [cell_m](const Vec3f& p) {
    const int64_t i = static_cast<int64_t>(std::floor(p.x / cell_m));
    const int64_t j = static_cast<int64_t>(std::floor(p.y / cell_m));
    return (static_cast<uint64_t>(static_cast<uint32_t>(i)) << 32) | static_cast<uint32_t>(j);
  };
  std::unordered_map<uint64_t, integrators::SlicePoint> cells;
  const Stream stream = Stream::create(config_.device);
  for (const auto& [submap, T_world_submap] : submaps) {
    // A sweep: brought back for this slice only, it is the first to leave again below.
    acquire_locked(*submap, /*mark_used=*/false);
    enforce_budget_locked(submap->id());
    for (const integrators::SlicePoint& point :
         world_slice_of(submap->map(), T_world_submap, height_m, stream)) {
      const uint64_t key = key_of(point.position_m);
      auto it = cells.find(key);
      if (it == cells.end()) {
        // Reported at the cell centre, so overlapping submaps give one point per cell.
        integrators::SlicePoint centred = point;
        const double i = std::floor(point.position_m.x / cell_m),
                     j = std::floor(point.position_m.y / cell_m);
        centred.position_m.x = static_cast<float>((i + 0.5) * cell_m);
        centred.position_m.y = static_cast<float>((j + 0.5) * cell_m);
        cells.emplace(key, centred);
      } else if (point.distance_m < it->second.distance_m) {
        it->second.distance_m = point.distance_m;
      }
    }
  }
  enforce_budget_locked(-1);
  std::vector<integrators::SlicePoint> merged;
  merged.reserve(cells.size());
  for (const auto& cell : cells) merged.push_back(cell.second);
  return merged;
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

// SlamSystem's map storage: finished submaps under the memory budget (pipeline/submap_store.h)
// and in their compact form (io/submap_codec.h) for map files.
#include <mutex>
#include <unordered_set>
#include <utility>
#include <vector>

#include "covoxslam/io/submap_codec.h"
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

void SlamSystem::write_submaps(const EncodedSubmapSink& write) {
  // backend_mutex_ keeps the graph's submaps (and their voxels) as they are while each is encoded;
  // state_mutex_ is held only to read a pose.
  std::lock_guard<std::mutex> structure_lock(backend_mutex_);
  std::vector<std::pair<const Submap*, Eigen::Isometry3d>> submaps;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const GraphSubmap& entry : graph_submaps_)
      submaps.emplace_back(entry.submap.get(), entry.submap->T_world_submap());
  }
  for (const auto& [submap, T_world_submap] : submaps) {
    // The store holds the compact form of every finished submap it manages (the same bytes the
    // submap was rebuilt from); without a budget the voxels are encoded here.
    std::vector<uint8_t> encoded = store_->encoded(submap->id());
    if (encoded.empty()) encoded = io::encode_submap(submap->map(), map_distance_scale_m());
    write(submap->id(), T_world_submap, encoded);
  }
}

bool SlamSystem::acquire_locked(Submap& submap, bool mark_used) {
  return store_->acquire(submap, restore_esdf_, restore_stream_, mark_used);
}

void SlamSystem::enforce_budget_locked(int64_t keep, const std::unordered_set<int64_t>& also_kept,
                                       bool return_memory) {
  if (!store_->enabled()) return;
  std::vector<Submap*> candidates;
  std::vector<WallMapCache*> candidate_walls;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    // kJoint solves read the field submaps of its pairs at every optimisation: they stay.
    std::unordered_set<int64_t> pinned = also_kept;
    for (const JointPair& pair : joint_pairs_) pinned.insert(pair.field_submap);
    for (const GraphSubmap& entry : graph_submaps_) {
      if (entry.submap && !pinned.count(entry.submap->id())) {
        candidates.push_back(entry.submap.get());
        candidate_walls.push_back(entry.walls.get());
      }
    }
  }
  store_->enforce(candidates, keep, return_memory);
  // A compacted submap's wall map goes with its voxels (wall_map.h): otherwise every finished
  // submap would keep one in host memory outside the budgets. Nothing reads the wall map of a
  // submap that is not resident: registration brings its partners back first.
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (candidates[i]->map().block_count() == 0) candidate_walls[i]->release();
  }
}

void SlamSystem::acquire_partners_locked(const std::vector<const RegistrationPartner*>& partners) {
  if (!store_->enabled() || partners.empty()) return;
  std::unordered_set<int64_t> wanted;
  for (const RegistrationPartner* partner : partners) wanted.insert(partner->id);
  std::vector<Submap*> chosen;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const GraphSubmap& entry : graph_submaps_) {
      if (entry.submap && wanted.count(entry.submap->id())) chosen.push_back(entry.submap.get());
    }
  }
  // The partners are the most recently used once acquired, so the submaps that leave to make room
  // are those that would leave after the registration anyway; leaving before the next partner
  // comes back keeps the device within the budget and one submap. The freed host memory is kept
  // for the next partner's restore and handed back by the enforcement after the registration.
  // The budget is enforced first (the new submap was added resident), then after each restore:
  // only a restore adds resident bytes, a partner already resident is only marked used.
  enforce_budget_locked(-1, wanted, /*return_memory=*/false);
  for (Submap* submap : chosen) {
    if (acquire_locked(*submap)) enforce_budget_locked(-1, wanted, /*return_memory=*/false);
  }
}

std::vector<SubmapSnapshot> SlamSystem::submap_snapshots() {
  std::lock_guard<std::mutex> structure_lock(backend_mutex_);
  std::vector<std::pair<Submap*, Eigen::Isometry3d>> submaps;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const GraphSubmap& entry : graph_submaps_)
      submaps.emplace_back(entry.submap.get(), entry.submap->T_world_submap());
  }
  std::vector<SubmapSnapshot> snapshots;
  snapshots.reserve(submaps.size());
  for (const auto& [submap, T_world_submap] : submaps) {
    acquire_locked(*submap, /*mark_used=*/false);
    snapshots.push_back(SubmapSnapshot{submap->id(), T_world_submap, submap->map().snapshot(), {}});
    enforce_budget_locked(submap->id());
  }
  enforce_budget_locked(-1);
  return snapshots;
}

}  // namespace pipeline
}  // namespace covox

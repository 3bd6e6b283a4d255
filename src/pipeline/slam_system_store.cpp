// SlamSystem's map storage: finished submaps in their compact form (io/submap_codec.h), for map
// files.
#include <mutex>
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
    write(submap->id(), T_world_submap, io::encode_submap(submap->map(), map_distance_scale_m()));
  }
}

}  // namespace pipeline
}  // namespace covox

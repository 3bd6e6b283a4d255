#pragma once
// PendingBlockMeshes: block meshes made on the device by MeshIntegrator::update() and not yet
// copied to the host. Each update appends its per-block welded vertices, colours, block-local
// triangles and per-block ranges with device-to-device copies, which do not wait for the device;
// apply_to() copies everything to the host once and replays the updates in order, so a block
// re-meshed twice ends with its latest mesh.
#include <cstdint>
#include <map>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/index3d.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/mesh_integrator.h"

namespace covox::integrators {

class PendingBlockMeshes {
 public:
  explicit PendingBlockMeshes(Device device);

  // Appends one per-block extraction (MeshWeld::kPerBlock) of `extraction.blocks`.
  void append(const MeshScratchBuffers& extraction, int64_t vertex_count, int64_t triangle_count,
              const Stream& stream);
  int64_t vertex_count() const { return vertices_used_; }
  bool empty() const { return updates_.empty(); }

  // Replays the pending updates into `block_meshes` (a block whose new mesh is empty is erased),
  // returns the blocks of the last update, and empties the log.
  std::vector<Index3D> apply_to(std::map<Index3D, map::Mesh>* block_meshes, const Stream& stream);

 private:
  struct Update {
    int64_t vertex_base, triangle_base, block_base, range_base, block_count;
  };
  Buffer<Vec3f> vertices_;
  Buffer<Rgb8> colors_;
  Buffer<uint32_t> triangles_;  // 3 per triangle, local to the triangle's block
  Buffer<Index3D> blocks_;
  Buffer<uint32_t> first_vertex_;  // block count + 1 per update, relative to the update
  Buffer<uint32_t> first_triangle_;
  int64_t vertices_used_ = 0, triangle_indices_used_ = 0, blocks_used_ = 0, ranges_used_ = 0;
  std::vector<Update> updates_;
};

}  // namespace covox::integrators

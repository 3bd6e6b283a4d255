#pragma once
// MeshIntegrator: marching cubes (marching_cubes.h) over the TSDF on the device, with colour,
// vertices shared between neighbouring triangles welded (one vertex per cube edge), either for
// the whole map or incrementally for the blocks whose TSDF changed since the last update.
#include <cstdint>
#include <map>
#include <memory>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {

struct MeshIntegratorConfig {
  // Cubes with a corner of less TSDF weight are not meshed (unobserved space has no surface).
  float min_weight = 1e-4f;
};

struct MeshUpdateStats {
  int64_t blocks_meshed = 0;
  int64_t triangles = 0;
};

class MeshIntegrator {
 public:
  explicit MeshIntegrator(const MeshIntegratorConfig& config = {});
  ~MeshIntegrator();
  MeshIntegrator(MeshIntegrator&&) noexcept;
  MeshIntegrator& operator=(MeshIntegrator&&) noexcept;

  // The mesh of the whole map, welded everywhere.
  Mesh extract_all(TsdfMap& map, const Stream& stream);
  // Re-meshes the blocks whose TSDF changed since the last update (and the blocks whose cubes
  // reach into them) and keeps one mesh per block, for incremental publishing.
  MeshUpdateStats update(TsdfMap& map, const Stream& stream);
  const std::map<Index3D, Mesh>& block_meshes() const { return block_meshes_; }
  // Blocks re-meshed by the last update().
  const std::vector<Index3D>& last_updated_blocks() const { return last_updated_; }
  // All block meshes as one mesh (vertices are not shared across block borders).
  Mesh combined_block_meshes() const;

 private:
  struct Scratch;
  MeshIntegratorConfig config_;
  std::unique_ptr<Scratch> scratch_;
  std::map<Index3D, Mesh> block_meshes_;
  std::vector<Index3D> last_updated_;
};

// Device result of one extraction: welded vertices, triangles, and for each triangle the
// position in the input block list of the block its cube belongs to.
struct MeshScratchBuffers {
  explicit MeshScratchBuffers(Device device)
      : blocks(device), slots(device), counts(device), offsets(device), keys(device), order(device),
        positions(device), colors(device), triangle_blocks(device), flags(device), vertex_ids(device),
        vertices(device), vertex_colors(device), triangles(device), all_blocks(device), all_slots(device),
        affected(device) {}
  Buffer<Index3D> blocks;
  Buffer<uint32_t> slots;
  Buffer<uint32_t> counts;
  Buffer<uint32_t> offsets;
  Buffer<uint64_t> keys;
  Buffer<uint32_t> order;
  Buffer<Vec3f> positions;
  Buffer<Rgb8> colors;
  Buffer<uint32_t> triangle_blocks;
  Buffer<uint32_t> flags;
  Buffer<uint32_t> vertex_ids;
  Buffer<Vec3f> vertices;
  Buffer<Rgb8> vertex_colors;
  Buffer<uint32_t> triangles;
  // choosing the blocks to re-mesh
  Buffer<Index3D> all_blocks;
  Buffer<uint32_t> all_slots;
  Buffer<uint32_t> affected;
};

// Meshes the cubes whose first corner lies in scratch.blocks (with slots). Returns the number of
// triangles; fills scratch.vertices / vertex_colors / triangles / triangle_blocks.
template <class Backend>
int64_t mesh_extract(Backend backend, TsdfMap& map, float min_weight, MeshScratchBuffers& scratch,
                     int64_t* vertex_count, const Stream& stream);

// Writes to scratch.blocks, sorted by packed key, the blocks whose meshes are out of date: those
// with kMeshPending set and the allocated blocks just below them; clears their kMeshPending bits
// on the device. Returns how many.
template <class Backend>
int64_t mesh_select_blocks(Backend backend, TsdfMap& map, MeshScratchBuffers& scratch, const Stream& stream);

}  // namespace covox

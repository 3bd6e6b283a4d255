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

namespace covox::integrators {

struct MeshIntegratorConfig {
  // Cubes with a corner of less TSDF weight are not meshed (unobserved space has no surface).
  float min_weight = 1e-4f;
  // Incremental updates weld vertices through a table of 3 (side + 1)^3 entries per re-meshed
  // block (12 bytes each with its scans) up to this many entries (about 200 MB), by a sort beyond.
  int64_t max_weld_table_entries = int64_t(1) << 24;
};

struct MeshUpdateStats {
  int64_t blocks_meshed = 0;
  int64_t triangles = 0;
};

// The slots of a block and of its neighbours at +x, +y, +z (index bit 0: +x, bit 1: +y, bit 2: +z),
// kInvalidSlot where a neighbour is not allocated: a cube's eight corners lie in these blocks.
struct BlockNeighbourSlots {
  uint32_t slots[8];
};

// How an extraction shares vertices between triangles: one vertex per cube edge over the whole
// input (kGlobal, what extract_all returns), or per block (kPerBlock: vertices and triangles
// grouped by block, triangle indices local to their block, for the block meshes of update()).
enum class MeshWeld { kGlobal, kPerBlock };

class PendingBlockMeshes;

class MeshIntegrator {
 public:
  explicit MeshIntegrator(const MeshIntegratorConfig& config = {});
  ~MeshIntegrator();
  MeshIntegrator(MeshIntegrator&&) noexcept;
  MeshIntegrator& operator=(MeshIntegrator&&) noexcept;

  // The mesh of the whole map, welded everywhere.
  map::Mesh extract_all(map::TsdfMap& map, const Stream& stream);
  // Re-meshes the blocks whose TSDF changed since the last update (and the blocks whose cubes
  // reach into them), one mesh per block for incremental publishing. The new block meshes stay
  // in device memory until block_meshes() or last_updated_blocks() asks for them (or about
  // kMaxPendingVertices have piled up), so a per-frame update makes no host copies.
  MeshUpdateStats update(map::TsdfMap& map, const Stream& stream);
  // One mesh per block, vertices welded inside the block. Brings pending updates to the host
  // first; `stream` is the one update() ran on (its copies are waited for).
  const std::map<Index3D, map::Mesh>& block_meshes(const Stream& stream);
  // Blocks re-meshed by the last update().
  const std::vector<Index3D>& last_updated_blocks(const Stream& stream);
  // All block meshes as one mesh (vertices are not shared across block borders).
  map::Mesh combined_block_meshes(const Stream& stream);

  // Pending device vertices above which update() brings the block meshes to the host itself.
  static constexpr int64_t kMaxPendingVertices = int64_t(1) << 24;

 private:
  void download_pending(const Stream& stream);
  struct Scratch;
  MeshIntegratorConfig config_;
  std::unique_ptr<Scratch> scratch_;
  std::unique_ptr<PendingBlockMeshes> pending_;
  std::map<Index3D, map::Mesh> block_meshes_;
  std::vector<Index3D> last_updated_;
};

// Device result of one extraction: welded vertices and triangles; with MeshWeld::kPerBlock also
// each input block's first vertex and first triangle (block count + 1 entries).
struct MeshScratchBuffers {
  explicit MeshScratchBuffers(Device device)
      : blocks(device),
        slots(device),
        counts(device),
        offsets(device),
        keys(device),
        order(device),
        positions(device),
        colors(device),
        flags(device),
        vertex_ids(device),
        vertices(device),
        vertex_colors(device),
        triangles(device),
        keys_alt(device),
        order_alt(device),
        neighbours(device),
        block_first_vertex(device),
        block_first_triangle(device),
        weld_table(device),
        affected(device) {}
  Buffer<Index3D> blocks;
  Buffer<uint32_t> slots;
  Buffer<uint32_t> counts;
  Buffer<uint32_t> offsets;
  Buffer<uint64_t> keys;
  Buffer<uint32_t> order;
  Buffer<Vec3f> positions;
  Buffer<Rgb8> colors;
  Buffer<uint32_t> flags;
  Buffer<uint32_t> vertex_ids;
  Buffer<Vec3f> vertices;
  Buffer<Rgb8> vertex_colors;
  Buffer<uint32_t> triangles;
  Buffer<uint64_t> keys_alt;
  Buffer<uint32_t> order_alt;
  Buffer<BlockNeighbourSlots> neighbours;
  Buffer<uint32_t> block_first_vertex;
  Buffer<uint32_t> block_first_triangle;
  Buffer<uint32_t> weld_table;
  // choosing the blocks to re-mesh
  Buffer<uint32_t> affected;
};

// Meshes the cubes whose first corner lies in scratch.blocks (kGlobal sorts them by block index
// first, so the mesh does not depend on the hash table's layout). Returns the number of triangles;
// fills scratch.vertices / vertex_colors / triangles (and the per-block ranges for kPerBlock).
// kPerBlock welds through a table of every input block's cube edges while it has at most
// `max_weld_table_entries` entries (3 (side + 1)^3 per block, 4 bytes each, plus two scan
// arrays), and by sorting the corners' block-local edge keys beyond: same result, the table
// needs no sort.
template <class Backend>
int64_t mesh_extract(Backend backend, map::TsdfMap& map, float min_weight, MeshWeld weld,
                     MeshScratchBuffers& scratch, int64_t* vertex_count, const Stream& stream,
                     int64_t max_weld_table_entries);

// Writes to scratch.blocks, in hash-table bucket order, the blocks whose meshes are out of date:
// those with kMeshPending set and the allocated blocks just below them; clears their
// kMeshPending bits on the device. Returns how many.
template <class Backend>
int64_t mesh_select_blocks(Backend backend, map::TsdfMap& map, MeshScratchBuffers& scratch,
                           const Stream& stream);

}  // namespace covox::integrators

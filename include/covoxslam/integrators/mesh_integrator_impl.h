#pragma once
// Marching-cubes extraction and vertex welding, written once for both backends.
#include "covoxslam/core/atomics.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/integrators/marching_cubes.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/map/block_voxel_indexer.h"

namespace covox {
namespace mesh_detail {

// A cube edge named globally: the voxel its start corner is, and its axis. Neighbouring cubes
// name a shared edge identically, which is what welds their vertices.
COVOX_HD_INLINE uint64_t edge_key(const Index3D& start, int axis) {
  constexpr int64_t kBias = int64_t(1) << 19;
  constexpr uint64_t kMask = (uint64_t(1) << 20) - 1;
  return ((static_cast<uint64_t>(start.x + kBias) & kMask) << 42) |
         ((static_cast<uint64_t>(start.y + kBias) & kMask) << 22) |
         ((static_cast<uint64_t>(start.z + kBias) & kMask) << 2) | static_cast<uint64_t>(axis);
}

struct CubeReader {
  BlockVoxelIndexer indexer;
  VoxelView<TsdfVoxel, Layout::kSoA> tsdf;
  VoxelView<ColorVoxel, Layout::kSoA> color;
  float min_weight;

  // Corner values and colours of the cube whose first corner is voxel `origin`; false when a
  // corner is unallocated or unobserved.
  COVOX_HD_INLINE bool read(const Index3D& origin, float* values, Rgb8* colors) const {
    for (int c = 0; c < 8; ++c) {
      const int64_t index = indexer.pool_index(origin + Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1));
      if (index < 0) return false;
      const TsdfVoxel voxel = tsdf.load(index);
      if (voxel.weight < min_weight) return false;
      values[c] = voxel.distance_m;
      const ColorVoxel cv = color.load(index);
      colors[c] = Rgb8{cv.r, cv.g, cv.b};
    }
    return true;
  }
};

COVOX_HD_INLINE Index3D cube_origin(const Index3D* blocks, int64_t cube, int32_t side, int64_t per_block) {
  const Index3D block = blocks[cube / per_block];
  const int64_t k = cube % per_block;
  return Index3D(block.x * side + static_cast<int32_t>(k % side), block.y * side + static_cast<int32_t>((k / side) % side),
                 block.z * side + static_cast<int32_t>(k / (side * side)));
}

}  // namespace mesh_detail

template <class Backend>
int64_t mesh_extract(Backend backend, TsdfMap& map, float min_weight, MeshScratchBuffers& scratch,
                     int64_t* vertex_count, const Stream& stream) {
  using namespace mesh_detail;
  *vertex_count = 0;
  const int64_t block_count = static_cast<int64_t>(scratch.blocks.size());
  const int32_t side = map.voxels_per_side();
  const int64_t per_block = map.voxels_per_block();
  const int64_t cubes = block_count * per_block;
  if (cubes == 0) return 0;
  const CubeReader reader{BlockVoxelIndexer{map.blocks().device_view(), side}, map.tsdf().view(), map.color().view(),
                          min_weight};
  const Index3D* blocks = scratch.blocks.data();

  // 1. triangles per cube
  scratch.counts.resize_discard(cubes + 1);
  scratch.offsets.resize_discard(cubes + 1);
  uint32_t* counts = scratch.counts.data();
  parallel_for(backend, stream, cubes + 1, [=] COVOX_HD(int64_t i) {
    counts[i] = 0;
    if (i == cubes) return;
    float values[8];
    Rgb8 colors[8];
    if (!reader.read(cube_origin(blocks, i, side, per_block), values, colors)) return;
    counts[i] = static_cast<uint32_t>(marching_cubes::polygonize(values, [](int, int, int) {}));
  });
  exclusive_scan(backend, stream, counts, cubes + 1, scratch.offsets.data());
  const int64_t triangle_count = scratch.offsets.element(cubes, stream);
  if (triangle_count == 0) return 0;

  // 2. emit triangle corners, named by global edge
  const int64_t corners = 3 * triangle_count;
  scratch.keys.resize_discard(corners);
  scratch.order.resize_discard(corners);
  scratch.positions.resize_discard(corners);
  scratch.colors.resize_discard(corners);
  scratch.triangle_blocks.resize_discard(triangle_count);
  uint64_t* keys = scratch.keys.data();
  uint32_t* order = scratch.order.data();
  Vec3f* positions = scratch.positions.data();
  Rgb8* corner_colors = scratch.colors.data();
  uint32_t* triangle_blocks = scratch.triangle_blocks.data();
  const uint32_t* offsets = scratch.offsets.data();
  const float voxel_size = map.voxel_size_m();
  parallel_for(backend, stream, cubes, [=] COVOX_HD(int64_t i) {
    if (counts[i] == 0) return;
    const Index3D origin = cube_origin(blocks, i, side, per_block);
    float values[8];
    Rgb8 colors[8];
    reader.read(origin, values, colors);
    int64_t t = offsets[i];
    marching_cubes::polygonize(values, [&](int a, int b, int c) {
      if (marching_cubes::needs_flip(values, a, b, c)) {
        const int swap = b;
        b = c;
        c = swap;
      }
      const int edges[3] = {a, b, c};
      for (int k = 0; k < 3; ++k) {
        const int e = edges[k], start = marching_cubes::edge_start(e), end = marching_cubes::edge_end(e);
        const int64_t slot = 3 * t + k;
        const Index3D start_voxel = origin + Index3D(start & 1, (start >> 1) & 1, (start >> 2) & 1);
        keys[slot] = edge_key(start_voxel, marching_cubes::edge_axis(e));
        order[slot] = static_cast<uint32_t>(slot);
        const Vec3f p = marching_cubes::crossing_point(values, e);
        positions[slot] = Vec3f((origin.x + 0.5f + p.x) * voxel_size, (origin.y + 0.5f + p.y) * voxel_size,
                                (origin.z + 0.5f + p.z) * voxel_size);
        const float f = marching_cubes::crossing_fraction(values, e);
        const Rgb8 ca = colors[start], cb = colors[end];
        corner_colors[slot] = Rgb8{static_cast<uint8_t>(ca.r + f * (cb.r - ca.r) + 0.5f),
                                   static_cast<uint8_t>(ca.g + f * (cb.g - ca.g) + 0.5f),
                                   static_cast<uint8_t>(ca.b + f * (cb.b - ca.b) + 0.5f)};
      }
      triangle_blocks[t] = static_cast<uint32_t>(i / per_block);
      ++t;
    });
  });

  // 3. weld: sort corners by edge, one vertex per distinct edge
  sort_by_key(backend, stream, keys, order, corners);
  scratch.flags.resize_discard(corners + 1);
  scratch.vertex_ids.resize_discard(corners + 1);
  uint32_t* flags = scratch.flags.data();
  parallel_for(backend, stream, corners + 1, [=] COVOX_HD(int64_t j) {
    flags[j] = (j < corners && (j == 0 || keys[j] != keys[j - 1])) ? 1u : 0u;
  });
  exclusive_scan(backend, stream, flags, corners + 1, scratch.vertex_ids.data());
  const int64_t vertices = scratch.vertex_ids.element(corners, stream);
  scratch.vertices.resize_discard(vertices);
  scratch.vertex_colors.resize_discard(vertices);
  scratch.triangles.resize_discard(corners);
  Vec3f* out_vertices = scratch.vertices.data();
  Rgb8* out_colors = scratch.vertex_colors.data();
  uint32_t* out_triangles = scratch.triangles.data();
  const uint32_t* first_ids = scratch.vertex_ids.data();
  parallel_for(backend, stream, corners, [=] COVOX_HD(int64_t j) {
    // The run of equal keys that j belongs to starts where the flag was set.
    const uint32_t id = first_ids[j] + flags[j] - 1;
    if (flags[j]) {
      out_vertices[id] = positions[order[j]];
      out_colors[id] = corner_colors[order[j]];
    }
    out_triangles[order[j]] = id;
  });
  stream.synchronize();
  *vertex_count = vertices;
  return triangle_count;
}

template <class Backend>
int64_t mesh_select_blocks(Backend backend, TsdfMap& map, MeshScratchBuffers& scratch, const Stream& stream) {
  map.blocks().export_entries(&scratch.all_blocks, &scratch.all_slots);
  const int64_t entries = static_cast<int64_t>(scratch.all_blocks.size());
  if (entries == 0) return 0;
  // Per slot: > 0 when the block's mesh must be redone.
  scratch.affected.resize_discard(map.blocks().slot_count());
  scratch.affected.fill_bytes(0, stream);
  uint32_t* affected = scratch.affected.data();
  uint8_t* changed = map.block_changed().data();
  const Index3D* all_blocks = scratch.all_blocks.data();
  const uint32_t* all_slots = scratch.all_slots.data();
  const BlockHashTableView table = map.blocks().device_view();
  parallel_for(backend, stream, entries, [=] COVOX_HD(int64_t i) {
    const uint32_t slot = all_slots[i];
    if (!(changed[slot] & kMeshPending)) return;
    changed[slot] = static_cast<uint8_t>(changed[slot] & ~kMeshPending);
    // A cube reads the block of its first corner and its +x/+y/+z neighbours, so a changed
    // block also changes the meshes of the seven blocks just below it.
    for (int c = 0; c < 8; ++c) {
      const Index3D below = all_blocks[i] - Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1);
      const uint64_t bucket = table.find(pack_block_key(below));
      if (bucket != kNoBucket) atomic_add(&affected[table.slots[bucket]], 1u);
    }
  });
  // Compact to the affected blocks' keys, sorted: the same order on both backends.
  scratch.flags.resize_discard(entries + 1);
  scratch.vertex_ids.resize_discard(entries + 1);
  uint32_t* flags = scratch.flags.data();
  parallel_for(backend, stream, entries + 1,
               [=] COVOX_HD(int64_t i) { flags[i] = i < entries && affected[all_slots[i]] > 0 ? 1u : 0u; });
  exclusive_scan(backend, stream, flags, entries + 1, scratch.vertex_ids.data());
  const int64_t selected = scratch.vertex_ids.element(entries, stream);
  scratch.keys.resize_discard(selected);
  scratch.blocks.resize_discard(selected);
  uint64_t* keys = scratch.keys.data();
  const uint32_t* positions = scratch.vertex_ids.data();
  parallel_for(backend, stream, entries, [=] COVOX_HD(int64_t i) {
    if (flags[i]) keys[positions[i]] = pack_block_key(all_blocks[i]);
  });
  sort(backend, stream, keys, selected);
  Index3D* blocks = scratch.blocks.data();
  parallel_for(backend, stream, selected, [=] COVOX_HD(int64_t i) { blocks[i] = unpack_block_key(keys[i]); });
  return selected;
}

#define COVOX_INSTANTIATE_MESH_INTEGRATOR(Backend)                                                    \
  template int64_t mesh_extract<Backend>(Backend, TsdfMap&, float, MeshScratchBuffers&, int64_t*, \
                                         const Stream&);                                                \
  template int64_t mesh_select_blocks<Backend>(Backend, TsdfMap&, MeshScratchBuffers&, const Stream&);

}  // namespace covox

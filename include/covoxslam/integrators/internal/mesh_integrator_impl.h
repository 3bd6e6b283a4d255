#pragma once
// Marching-cubes extraction, vertex welding and the choice of blocks to re-mesh, written once
// for both backends.
#include "covoxslam/core/atomics.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/radix_sort.h"
#include "covoxslam/core/sorted_search.h"
#include "covoxslam/integrators/internal/marching_cubes.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/map/block_key.h"
#include "covoxslam/map/block_voxel_indexer.h"

namespace covox::integrators {
namespace internal {

// A cube edge named globally: the voxel its start corner is, and its axis. Neighbouring cubes
// name a shared edge identically, which is what welds their vertices.
COVOX_HD_INLINE uint64_t edge_key(const Index3D& start, int axis) {
  constexpr int64_t kBias = int64_t(1) << 19;
  constexpr uint64_t kMask = (uint64_t(1) << 20) - 1;
  return ((static_cast<uint64_t>(start.x + kBias) & kMask) << 42) |
         ((static_cast<uint64_t>(start.y + kBias) & kMask) << 22) |
         ((static_cast<uint64_t>(start.z + kBias) & kMask) << 2) | static_cast<uint64_t>(axis);
}

// A cube edge named inside one block, for the per-block weld: its start voxel relative to the
// block's first voxel (0..side on each axis, since the cubes of the block's last layer end in
// the next block) and its axis. Fits in bits_for(3 (side + 1)^3 - 1) bits: 12 for side 8.
COVOX_HD_INLINE uint32_t local_edge_key(int32_t x, int32_t y, int32_t z, int axis, int32_t side) {
  const uint32_t n = static_cast<uint32_t>(side) + 1u;
  return ((static_cast<uint32_t>(z) * n + static_cast<uint32_t>(y)) * n +
          static_cast<uint32_t>(x)) *
             3u +
         static_cast<uint32_t>(axis);
}
inline int local_edge_bits(int32_t side) {
  return bits_for(3ull * (side + 1) * (side + 1) * (side + 1) - 1);
}

// Reads a cube's eight corners from the slots of its block and of the block's +x/+y/+z
// neighbours (found once per block), not with eight hash probes per cube.
struct CubeReader {
  const BlockNeighbourSlots* neighbours;
  int32_t side;
  VoxelView<map::TsdfVoxel, Layout::kSoA> tsdf;
  VoxelView<map::ColorVoxel, Layout::kSoA> color;
  float min_weight;

  // Corner values and colours of the cube whose first corner is voxel `local` of the input's
  // block `block`; false when a corner is unallocated or unobserved.
  COVOX_HD_INLINE bool read(int64_t block, const Index3D& local, float* values,
                            Rgb8* colors) const {
    const BlockNeighbourSlots& around = neighbours[block];
    const int64_t per_block = static_cast<int64_t>(side) * side * side;
    for (int c = 0; c < 8; ++c) {
      int32_t x = local.x + (c & 1), y = local.y + ((c >> 1) & 1), z = local.z + ((c >> 2) & 1);
      int which = 0;  // bit 0: the corner lies in the +x block, bit 1: +y, bit 2: +z
      if (x == side) x = 0, which |= 1;
      if (y == side) y = 0, which |= 2;
      if (z == side) z = 0, which |= 4;
      const uint32_t slot = around.slots[which];
      if (slot == map::kInvalidSlot) return false;
      const int64_t index =
          static_cast<int64_t>(slot) * per_block + x + side * (y + static_cast<int64_t>(side) * z);
      const map::TsdfVoxel voxel = tsdf.load(index);
      if (voxel.weight < min_weight) return false;
      values[c] = voxel.distance_m;
      const map::ColorVoxel cv = color.load(index);
      colors[c] = Rgb8{cv.r, cv.g, cv.b};
    }
    return true;
  }
};

struct MeshOutputs {
  Vec3f* vertices;
  Rgb8* colors;
  uint32_t* triangles;
};
inline MeshOutputs size_outputs(MeshScratchBuffers& scratch, int64_t vertices, int64_t corners) {
  scratch.vertices.resize_discard(vertices);
  scratch.vertex_colors.resize_discard(vertices);
  scratch.triangles.resize_discard(corners);
  return MeshOutputs{scratch.vertices.data(), scratch.vertex_colors.data(),
                     scratch.triangles.data()};
}

// Each input block's first vertex (first_vertex(b), b in [0, blocks]) and first triangle (that of
// its first cube) for the per-block weld.
template <class Backend, class FirstVertex>
void write_block_ranges(Backend backend, const Stream& stream, MeshScratchBuffers& scratch,
                        int64_t block_count, int64_t per_block, const uint32_t* triangle_offsets,
                        FirstVertex first_vertex) {
  uint32_t* block_first_vertex = scratch.block_first_vertex.data();
  uint32_t* block_first_triangle = scratch.block_first_triangle.data();
  parallel_for(backend, stream, block_count + 1, [=] COVOX_HD(int64_t b) {
    block_first_vertex[b] = first_vertex(b);
    block_first_triangle[b] = triangle_offsets[b * per_block];
  });
}

// The first vertex of input block b under the table weld: the number of claimed entries before
// the block's part of the table.
struct TableFirstVertex {
  const uint32_t* ids;
  uint32_t edges_per_block;
  COVOX_HD_INLINE uint32_t operator()(int64_t b) const { return ids[b * edges_per_block]; }
};
// ... and under the sorted weld: the vertex of the first key of block b (keys are block-major).
struct SortedFirstVertex {
  const uint32_t* first_ids;
  const uint64_t* keys;
  int64_t corners;
  int edge_bits;
  COVOX_HD_INLINE uint32_t operator()(int64_t b) const {
    return first_ids[lower_bound_index(keys, corners, static_cast<uint64_t>(b) << edge_bits)];
  }
};

// The sizes one extraction works with, fixed by the input blocks and the map.
struct ExtractShape {
  int64_t block_count;
  int64_t per_block;  // voxels (cubes) per block
  int64_t cubes;
  int32_t side;
  int edge_bits;             // bits of a block-local edge key
  uint32_t edges_per_block;  // block-local edge keys: 3 (side + 1)^3
};

// Kernel: the number of triangles of each cube, 0 for a cube that cannot be read and for the
// extra entry `cubes` (so that the exclusive scan's last entry is the total).
struct CountCubeTriangles {
  CubeReader reader;
  uint32_t* counts;
  int64_t cubes;
  int64_t per_block;
  int32_t side;
  COVOX_HD_INLINE void operator()(int64_t i) const {
    counts[i] = 0;
    if (i == cubes) return;
    float values[8];
    Rgb8 colors[8];
    if (!reader.read(i / per_block, map::local_voxel(i % per_block, side), values, colors)) return;
    counts[i] = static_cast<uint32_t>(marching_cubes::polygonize(values, [](int, int, int) {}));
  }
};

// How a triangle corner is named for the weld: by its global edge key (kGlobal); under
// kPerBlock, by (block, local edge), either as an index into the dense weld table (`table` set:
// the entry is claimed by the smallest corner on it, the one a stable sort would keep first) or
// as a sort key with the block in the bits above the local edge.
struct CornerNaming {
  bool per_block_weld;
  uint32_t* table;
  uint32_t edges_per_block;
  int edge_bits;
  int32_t side;
  COVOX_HD_INLINE uint64_t key(int64_t block, const Index3D& origin, const Index3D& local,
                               const Index3D& offset, int axis, int64_t slot) const {
    if (!per_block_weld) return edge_key(origin + offset, axis);
    const uint32_t local_edge =
        local_edge_key(local.x + offset.x, local.y + offset.y, local.z + offset.z, axis, side);
    if (!table) return (static_cast<uint64_t>(block) << edge_bits) | local_edge;
    const uint64_t entry = static_cast<uint64_t>(block) * edges_per_block + local_edge;
    atomic_min(&table[entry], static_cast<uint32_t>(slot));
    return entry;
  }
};

// Per triangle corner (3 per triangle, in triangle order): its weld key, its own index (the
// sort's payload), its position and its colour.
struct CornerArrays {
  uint64_t* keys;
  uint32_t* order;
  Vec3f* positions;
  Rgb8* colors;
};

// Kernel: writes the corners of each cube's triangles from the cube's first triangle on,
// triangles wound consistently (marching_cubes::needs_flip), corners placed at the edge
// crossings with colours interpolated between the edge's end voxels.
struct EmitCubeCorners {
  CubeReader reader;
  const Index3D* blocks;
  const uint32_t* counts;
  const uint32_t* offsets;
  CornerNaming naming;
  CornerArrays out;
  int64_t per_block;
  int32_t side;
  float voxel_size;

  COVOX_HD_INLINE void operator()(int64_t i) const {
    if (counts[i] == 0) return;
    const int64_t block = i / per_block;
    const Index3D local = map::local_voxel(i % per_block, side);
    const Index3D origin(blocks[block].x * side + local.x, blocks[block].y * side + local.y,
                         blocks[block].z * side + local.z);
    float values[8];
    Rgb8 colors[8];
    reader.read(block, local, values, colors);
    int64_t t = offsets[i];
    marching_cubes::polygonize(values, [&](int a, int b, int c) {
      if (marching_cubes::needs_flip(values, a, b, c)) {
        const int swap = b;
        b = c;
        c = swap;
      }
      const int edges[3] = {a, b, c};
      for (int k = 0; k < 3; ++k) corner(3 * t + k, edges[k], block, local, origin, values, colors);
      ++t;
    });
  }

  COVOX_HD_INLINE void corner(int64_t slot, int e, int64_t block, const Index3D& local,
                              const Index3D& origin, const float* values,
                              const Rgb8* colors) const {
    const int start = marching_cubes::edge_start(e), end = marching_cubes::edge_end(e);
    const Index3D offset(start & 1, (start >> 1) & 1, (start >> 2) & 1);
    out.keys[slot] = naming.key(block, origin, local, offset, marching_cubes::edge_axis(e), slot);
    out.order[slot] = static_cast<uint32_t>(slot);
    const Vec3f p = marching_cubes::crossing_point(values, e);
    out.positions[slot] =
        Vec3f((origin.x + 0.5f + p.x) * voxel_size, (origin.y + 0.5f + p.y) * voxel_size,
              (origin.z + 0.5f + p.z) * voxel_size);
    const float f = marching_cubes::crossing_fraction(values, e);
    const Rgb8 ca = colors[start], cb = colors[end];
    out.colors[slot] = Rgb8{static_cast<uint8_t>(ca.r + f * (cb.r - ca.r) + 0.5f),
                            static_cast<uint8_t>(ca.g + f * (cb.g - ca.g) + 0.5f),
                            static_cast<uint8_t>(ca.b + f * (cb.b - ca.b) + 0.5f)};
  }
};

// Kernel: 1 for each claimed weld table entry, 0 for the others and for the extra last entry.
struct MarkClaimedEntries {
  const uint32_t* table;
  uint32_t* claimed;
  int64_t table_entries;
  COVOX_HD_INLINE void operator()(int64_t e) const {
    claimed[e] = e < table_entries && table[e] != map::kInvalidSlot ? 1u : 0u;
  }
};

// Kernel: each claimed table entry's vertex is the corner that claimed it.
struct WriteTableVertices {
  const uint32_t* claimed;
  const uint32_t* ids;
  const uint32_t* table;
  const Vec3f* positions;
  const Rgb8* corner_colors;
  MeshOutputs out;
  COVOX_HD_INLINE void operator()(int64_t e) const {
    if (!claimed[e]) return;
    out.vertices[ids[e]] = positions[table[e]];
    out.colors[ids[e]] = corner_colors[table[e]];
  }
};

// Kernel: each corner's vertex, numbered from its block's first vertex.
struct WriteTableTriangles {
  const uint32_t* ids;
  const uint64_t* keys;
  const uint32_t* block_first_vertex;
  uint32_t edges_per_block;
  MeshOutputs out;
  COVOX_HD_INLINE void operator()(int64_t j) const {
    out.triangles[j] = ids[keys[j]] - block_first_vertex[keys[j] / edges_per_block];
  }
};

// Kernel: 1 where a run of equal sorted keys starts, 0 elsewhere and for the extra last entry.
struct MarkFirstOfRun {
  const uint64_t* keys;
  uint32_t* flags;
  int64_t corners;
  COVOX_HD_INLINE void operator()(int64_t j) const {
    flags[j] = (j < corners && (j == 0 || keys[j] != keys[j - 1])) ? 1u : 0u;
  }
};

// Kernel: the first corner of each run of equal keys gives the run's vertex; every corner's
// triangle entry (at its position before the sort) gets the run's vertex, numbered from its
// block's first vertex when `block_first_vertex` is set.
struct WriteSortedMesh {
  const uint32_t* first_ids;
  const uint32_t* flags;
  const uint32_t* order;
  const uint64_t* keys;
  const uint32_t* block_first_vertex;
  const Vec3f* positions;
  const Rgb8* corner_colors;
  int edge_bits;
  MeshOutputs out;
  COVOX_HD_INLINE void operator()(int64_t j) const {
    // The run of equal keys that j belongs to starts where the flag was set.
    const uint32_t id = first_ids[j] + flags[j] - 1;
    if (flags[j]) {
      out.vertices[id] = positions[order[j]];
      out.colors[id] = corner_colors[order[j]];
    }
    out.triangles[order[j]] =
        block_first_vertex ? id - block_first_vertex[keys[j] >> edge_bits] : id;
  }
};

inline ExtractShape extract_shape(const map::TsdfMap& map, const MeshScratchBuffers& scratch) {
  ExtractShape shape;
  shape.block_count = static_cast<int64_t>(scratch.blocks.size());
  shape.side = map.voxels_per_side();
  shape.per_block = map.voxels_per_block();
  shape.cubes = shape.block_count * shape.per_block;
  shape.edge_bits = local_edge_bits(shape.side);
  shape.edges_per_block =
      3u * static_cast<uint32_t>((shape.side + 1) * (shape.side + 1) * (shape.side + 1));
  return shape;
}

// Per-block ranges start empty: an extraction that finds no triangle leaves them so.
inline void clear_block_ranges(MeshScratchBuffers& scratch, int64_t block_count,
                               const Stream& stream) {
  scratch.block_first_vertex.resize_discard(block_count + 1);
  scratch.block_first_triangle.resize_discard(block_count + 1);
  scratch.block_first_vertex.fill_bytes(0, stream);
  scratch.block_first_triangle.fill_bytes(0, stream);
}

// Stage 1: triangles per cube and each cube's first triangle (scratch.offsets). Returns the
// triangle count.
template <class Backend>
int64_t count_triangles(Backend backend, const Stream& stream, const CubeReader& reader,
                        const ExtractShape& shape, MeshScratchBuffers& scratch) {
  const int64_t cubes = shape.cubes;
  scratch.counts.resize_discard(cubes + 1);
  scratch.offsets.resize_discard(cubes + 1);
  uint32_t* counts = scratch.counts.data();
  parallel_for(backend, stream, cubes + 1,
               CountCubeTriangles{reader, counts, cubes, shape.per_block, shape.side});
  exclusive_scan(backend, stream, counts, cubes + 1, scratch.offsets.data());
  return scratch.offsets.element(cubes, stream);
}

// Stage 2: the triangle corners, named by their edge (globally, or inside their block). With
// `weld_table` the table of every block's edges is reset first and claimed by the corners.
template <class Backend>
void emit_corners(Backend backend, const Stream& stream, const CubeReader& reader,
                  const ExtractShape& shape, bool per_block_weld, bool weld_table, float voxel_size,
                  int64_t corners, MeshScratchBuffers& scratch) {
  scratch.keys.resize_discard(corners);
  scratch.order.resize_discard(corners);
  scratch.positions.resize_discard(corners);
  scratch.colors.resize_discard(corners);
  const CornerArrays out{scratch.keys.data(), scratch.order.data(), scratch.positions.data(),
                         scratch.colors.data()};
  uint32_t* table = nullptr;
  if (weld_table) {
    scratch.weld_table.resize_discard(shape.block_count * shape.edges_per_block);
    scratch.weld_table.fill_bytes(0xff, stream);
    table = scratch.weld_table.data();
  }
  const CornerNaming naming{per_block_weld, table, shape.edges_per_block, shape.edge_bits,
                            shape.side};
  parallel_for(
      backend, stream, shape.cubes,
      EmitCubeCorners{reader, scratch.blocks.data(), scratch.counts.data(), scratch.offsets.data(),
                      naming, out, shape.per_block, shape.side, voxel_size});
}

// Stage 3 with the table: claimed entries, in (block, local edge) order, are the vertices; the
// same numbering as the sorted weld's. Returns the vertex count.
template <class Backend>
int64_t weld_with_table(Backend backend, const Stream& stream, const ExtractShape& shape,
                        int64_t corners, MeshScratchBuffers& scratch) {
  const int64_t table_entries = shape.block_count * shape.edges_per_block;
  const uint32_t* table = scratch.weld_table.data();
  scratch.flags.resize_discard(table_entries + 1);
  scratch.vertex_ids.resize_discard(table_entries + 1);
  uint32_t* claimed = scratch.flags.data();
  parallel_for(backend, stream, table_entries + 1,
               MarkClaimedEntries{table, claimed, table_entries});
  exclusive_scan(backend, stream, claimed, table_entries + 1, scratch.vertex_ids.data());
  const int64_t vertices = scratch.vertex_ids.element(table_entries, stream);
  const uint32_t* ids = scratch.vertex_ids.data();
  write_block_ranges(backend, stream, scratch, shape.block_count, shape.per_block,
                     scratch.offsets.data(), TableFirstVertex{ids, shape.edges_per_block});
  const uint32_t* block_first_vertex = scratch.block_first_vertex.data();
  const MeshOutputs out = size_outputs(scratch, vertices, corners);
  parallel_for(backend, stream, table_entries,
               WriteTableVertices{claimed, ids, table, scratch.positions.data(),
                                  scratch.colors.data(), out});
  parallel_for(backend, stream, corners,
               WriteTableTriangles{ids, scratch.keys.data(), block_first_vertex,
                                   shape.edges_per_block, out});
  return vertices;
}

// Sorts the corners by key, carrying their indices. Per-block keys need only bits_for(blocks) +
// edge_bits bits, so their radix sort runs only the passes those bits need; `keys` and `order`
// then name whichever pair of arrays holds the result.
template <class Backend>
void sort_corners(Backend backend, const Stream& stream, const ExtractShape& shape,
                  bool per_block_weld, int64_t corners, MeshScratchBuffers& scratch,
                  uint64_t*& keys, uint32_t*& order) {
  if (!per_block_weld) {
    sort_by_key(backend, stream, keys, order, corners);
    return;
  }
  scratch.keys_alt.resize_discard(corners);
  scratch.order_alt.resize_discard(corners);
  uint64_t* keys_alt = scratch.keys_alt.data();
  uint32_t* order_alt = scratch.order_alt.data();
  radix_sort_pairs_swapping(backend, stream, keys, order, corners,
                            bits_for(static_cast<uint64_t>(shape.block_count)) + shape.edge_bits,
                            keys_alt, order_alt);
}

// Stage 3 by sorting: corners sorted by edge, one vertex per distinct edge. Returns the vertex
// count.
template <class Backend>
int64_t weld_by_sorting(Backend backend, const Stream& stream, const ExtractShape& shape,
                        bool per_block_weld, int64_t corners, MeshScratchBuffers& scratch) {
  uint64_t* keys = scratch.keys.data();
  uint32_t* order = scratch.order.data();
  sort_corners(backend, stream, shape, per_block_weld, corners, scratch, keys, order);
  scratch.flags.resize_discard(corners + 1);
  scratch.vertex_ids.resize_discard(corners + 1);
  uint32_t* flags = scratch.flags.data();
  parallel_for(backend, stream, corners + 1, MarkFirstOfRun{keys, flags, corners});
  exclusive_scan(backend, stream, flags, corners + 1, scratch.vertex_ids.data());
  const int64_t vertices = scratch.vertex_ids.element(corners, stream);
  const uint32_t* first_ids = scratch.vertex_ids.data();
  const uint32_t* block_first_vertex = nullptr;
  if (per_block_weld) {
    write_block_ranges(backend, stream, scratch, shape.block_count, shape.per_block,
                       scratch.offsets.data(),
                       SortedFirstVertex{first_ids, keys, corners, shape.edge_bits});
    block_first_vertex = scratch.block_first_vertex.data();
  }
  const MeshOutputs out = size_outputs(scratch, vertices, corners);
  parallel_for(
      backend, stream, corners,
      WriteSortedMesh{first_ids, flags, order, keys, block_first_vertex, scratch.positions.data(),
                      scratch.colors.data(), shape.edge_bits, out});
  return vertices;
}

}  // namespace internal

template <class Backend>
void mesh_find_neighbour_slots(Backend backend, map::TsdfMap& map, MeshScratchBuffers& scratch,
                               const Stream& stream) {
  const int64_t block_count = static_cast<int64_t>(scratch.blocks.size());
  scratch.neighbours.resize_discard(block_count);
  const Index3D* blocks = scratch.blocks.data();
  BlockNeighbourSlots* neighbours = scratch.neighbours.data();
  const map::BlockHashTableView table = map.blocks().device_view();
  parallel_for(backend, stream, 8 * block_count, [=] COVOX_HD(int64_t i) {
    const int c = static_cast<int>(i % 8);
    neighbours[i / 8].slots[c] =
        table.slot_of(blocks[i / 8] + Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1));
  });
}

// Stage 0 of a whole-map extraction: scratch.blocks in increasing packed-key order. The hash
// table exports its blocks in bucket order, and blocks whose keys collide land in the order their
// inserts won (timing-dependent on either backend), so without this the same map could give its
// triangles in another order; the welded mesh is then a function of the map alone.
template <class Backend>
void sort_blocks_by_index(Backend backend, MeshScratchBuffers& scratch, const Stream& stream) {
  const int64_t count = static_cast<int64_t>(scratch.blocks.size());
  if (count < 2) return;
  scratch.keys.resize_discard(count);
  scratch.order.resize_discard(count);
  scratch.keys_alt.resize_discard(count);
  scratch.order_alt.resize_discard(count);
  Index3D* blocks = scratch.blocks.data();
  uint64_t* keys = scratch.keys.data();
  uint32_t* order = scratch.order.data();
  parallel_for(backend, stream, count, [=] COVOX_HD(int64_t i) {
    keys[i] = map::pack_block_key(blocks[i]);
    order[i] = static_cast<uint32_t>(i);
  });
  radix_sort_pairs(backend, stream, keys, order, count, 3 * map::kBlockKeyBitsPerAxis,
                   scratch.keys_alt.data(), scratch.order_alt.data());
  parallel_for(backend, stream, count,
               [=] COVOX_HD(int64_t i) { blocks[i] = map::unpack_block_key(keys[i]); });
}

template <class Backend>
int64_t mesh_extract(Backend backend, map::TsdfMap& map, float min_weight, MeshWeld weld,
                     MeshScratchBuffers& scratch, int64_t* vertex_count, const Stream& stream,
                     int64_t max_weld_table_entries) {
  using namespace internal;
  *vertex_count = 0;
  const bool per_block_weld = weld == MeshWeld::kPerBlock;
  // Per-block meshes are kept by block index, so only the whole-map mesh needs the order.
  if (!per_block_weld) sort_blocks_by_index(backend, scratch, stream);
  const ExtractShape shape = extract_shape(map, scratch);
  if (per_block_weld) clear_block_ranges(scratch, shape.block_count, stream);
  if (shape.cubes == 0) return 0;
  mesh_find_neighbour_slots(backend, map, scratch, stream);
  const CubeReader reader{scratch.neighbours.data(), shape.side, map.tsdf().view(),
                          map.color().view(), min_weight};
  const int64_t triangle_count = count_triangles(backend, stream, reader, shape, scratch);
  if (triangle_count == 0) return 0;
  const int64_t corners = 3 * triangle_count;
  // The per-block weld goes through a dense table of every block's edges (one entry per block
  // and local edge, claimed by the first corner on it) when the table is small enough; else, and
  // for the global weld, by sorting.
  const bool weld_table =
      per_block_weld && shape.block_count * shape.edges_per_block <= max_weld_table_entries;
  emit_corners(backend, stream, reader, shape, per_block_weld, weld_table, map.voxel_size_m(),
               corners, scratch);
  *vertex_count = weld_table
                      ? weld_with_table(backend, stream, shape, corners, scratch)
                      : weld_by_sorting(backend, stream, shape, per_block_weld, corners, scratch);
  return triangle_count;
}

template <class Backend>
int64_t mesh_select_blocks(Backend backend, map::TsdfMap& map, MeshScratchBuffers& scratch,
                           const Stream& stream) {
  const map::BlockHashTableView table = map.blocks().device_view();
  const int64_t buckets = static_cast<int64_t>(table.bucket_count);
  const int64_t slot_count = map.blocks().slot_count();
  if (map.block_count() == 0 || slot_count == 0) {
    scratch.blocks.resize_discard(0);
    return 0;
  }
  // Per slot: > 0 when the block's mesh must be redone. The table is walked bucket by bucket
  // (no export of its entries first).
  scratch.affected.resize_discard(slot_count);
  scratch.affected.fill_bytes(0, stream);
  uint32_t* affected = scratch.affected.data();
  uint8_t* changed = map.block_changed().data();
  parallel_for(backend, stream, buckets, [=] COVOX_HD(int64_t b) {
    const uint64_t key = table.keys[b];
    if (!map::is_live_block_key(key)) return;
    const uint32_t slot = table.slots[b];
    if (!(changed[slot] & map::kMeshPending)) return;
    changed[slot] = static_cast<uint8_t>(changed[slot] & ~map::kMeshPending);
    // A cube reads the block of its first corner and its +x/+y/+z neighbours, so a changed
    // block also changes the meshes of the seven blocks just below it.
    const Index3D block = map::unpack_block_key(key);
    for (int c = 0; c < 8; ++c) {
      const uint32_t below = table.slot_of(block - Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1));
      if (below != map::kInvalidSlot) atomic_add(&affected[below], 1u);
    }
  });
  // Compact to the affected blocks, in bucket order (each block's mesh depends only on the
  // block, not on this order).
  scratch.flags.resize_discard(buckets + 1);
  scratch.vertex_ids.resize_discard(buckets + 1);
  uint32_t* flags = scratch.flags.data();
  parallel_for(backend, stream, buckets + 1, [=] COVOX_HD(int64_t b) {
    flags[b] = b < buckets && map::is_live_block_key(table.keys[b]) && affected[table.slots[b]] > 0
                   ? 1u
                   : 0u;
  });
  exclusive_scan(backend, stream, flags, buckets + 1, scratch.vertex_ids.data());
  const int64_t selected = scratch.vertex_ids.element(buckets, stream);
  scratch.blocks.resize_discard(selected);
  Index3D* blocks = scratch.blocks.data();
  const uint32_t* ranks = scratch.vertex_ids.data();
  parallel_for(backend, stream, buckets, [=] COVOX_HD(int64_t b) {
    if (flags[b]) blocks[ranks[b]] = map::unpack_block_key(table.keys[b]);
  });
  return selected;
}

#define COVOX_INSTANTIATE_MESH_INTEGRATOR(Backend)                                               \
  template int64_t mesh_extract<Backend>(Backend, map::TsdfMap&, float, MeshWeld,                \
                                         MeshScratchBuffers&, int64_t*, const Stream&, int64_t); \
  template int64_t mesh_select_blocks<Backend>(Backend, map::TsdfMap&, MeshScratchBuffers&,      \
                                               const Stream&);

}  // namespace covox::integrators

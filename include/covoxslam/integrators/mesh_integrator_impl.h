#pragma once
// Marching-cubes extraction, vertex welding and the choice of blocks to re-mesh, written once
// for both backends.
#include "covoxslam/core/atomics.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/core/radix_sort.h"
#include "covoxslam/core/sorted_search.h"
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
  VoxelView<TsdfVoxel, Layout::kSoA> tsdf;
  VoxelView<ColorVoxel, Layout::kSoA> color;
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
      if (slot == kInvalidSlot) return false;
      const int64_t index =
          static_cast<int64_t>(slot) * per_block + x + side * (y + static_cast<int64_t>(side) * z);
      const TsdfVoxel voxel = tsdf.load(index);
      if (voxel.weight < min_weight) return false;
      values[c] = voxel.distance_m;
      const ColorVoxel cv = color.load(index);
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

}  // namespace mesh_detail

template <class Backend>
void mesh_find_neighbour_slots(Backend backend, TsdfMap& map, MeshScratchBuffers& scratch,
                               const Stream& stream) {
  const int64_t block_count = static_cast<int64_t>(scratch.blocks.size());
  scratch.neighbours.resize_discard(block_count);
  const Index3D* blocks = scratch.blocks.data();
  BlockNeighbourSlots* neighbours = scratch.neighbours.data();
  const BlockHashTableView table = map.blocks().device_view();
  parallel_for(backend, stream, 8 * block_count, [=] COVOX_HD(int64_t i) {
    const int c = static_cast<int>(i % 8);
    neighbours[i / 8].slots[c] =
        table.slot_of(blocks[i / 8] + Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1));
  });
}

template <class Backend>
int64_t mesh_extract(Backend backend, TsdfMap& map, float min_weight, MeshWeld weld,
                     MeshScratchBuffers& scratch, int64_t* vertex_count, const Stream& stream,
                     int64_t max_weld_table_entries) {
  using namespace mesh_detail;
  *vertex_count = 0;
  const int64_t block_count = static_cast<int64_t>(scratch.blocks.size());
  const int32_t side = map.voxels_per_side();
  const int64_t per_block = map.voxels_per_block();
  const int64_t cubes = block_count * per_block;
  const bool per_block_weld = weld == MeshWeld::kPerBlock;
  if (per_block_weld) {  // empty ranges until the triangles are known
    scratch.block_first_vertex.resize_discard(block_count + 1);
    scratch.block_first_triangle.resize_discard(block_count + 1);
    scratch.block_first_vertex.fill_bytes(0, stream);
    scratch.block_first_triangle.fill_bytes(0, stream);
  }
  if (cubes == 0) return 0;
  mesh_find_neighbour_slots(backend, map, scratch, stream);
  const CubeReader reader{scratch.neighbours.data(), side, map.tsdf().view(), map.color().view(),
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
    if (!reader.read(i / per_block, local_voxel(i % per_block, side), values, colors)) return;
    counts[i] = static_cast<uint32_t>(marching_cubes::polygonize(values, [](int, int, int) {}));
  });
  exclusive_scan(backend, stream, counts, cubes + 1, scratch.offsets.data());
  const int64_t triangle_count = scratch.offsets.element(cubes, stream);
  if (triangle_count == 0) return 0;

  // 2. emit triangle corners, named by their edge (globally, or inside their block)
  const int64_t corners = 3 * triangle_count;
  scratch.keys.resize_discard(corners);
  scratch.order.resize_discard(corners);
  scratch.positions.resize_discard(corners);
  scratch.colors.resize_discard(corners);
  uint64_t* keys = scratch.keys.data();
  uint32_t* order = scratch.order.data();
  Vec3f* positions = scratch.positions.data();
  Rgb8* corner_colors = scratch.colors.data();
  const uint32_t* offsets = scratch.offsets.data();
  const float voxel_size = map.voxel_size_m();
  const int edge_bits = local_edge_bits(side);
  // Per-block weld through a dense table of every block's edges (one entry per block and local
  // edge, claimed by the first corner on it) when the table is small enough; else by sorting.
  const uint32_t edges_per_block = 3u * static_cast<uint32_t>((side + 1) * (side + 1) * (side + 1));
  const int64_t table_entries = block_count * edges_per_block;
  const bool weld_table = per_block_weld && table_entries <= max_weld_table_entries;
  uint32_t* table = nullptr;
  if (weld_table) {
    scratch.weld_table.resize_discard(table_entries);
    scratch.weld_table.fill_bytes(0xff, stream);
    table = scratch.weld_table.data();
  }
  parallel_for(backend, stream, cubes, [=] COVOX_HD(int64_t i) {
    if (counts[i] == 0) return;
    const int64_t block = i / per_block;
    const Index3D local = local_voxel(i % per_block, side);
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
      for (int k = 0; k < 3; ++k) {
        const int e = edges[k], start = marching_cubes::edge_start(e),
                  end = marching_cubes::edge_end(e);
        const int64_t slot = 3 * t + k;
        const Index3D offset(start & 1, (start >> 1) & 1, (start >> 2) & 1);
        const int axis = marching_cubes::edge_axis(e);
        if (!per_block_weld) {
          keys[slot] = edge_key(origin + offset, axis);
        } else {
          const uint32_t local_edge = local_edge_key(local.x + offset.x, local.y + offset.y,
                                                     local.z + offset.z, axis, side);
          if (table) {  // the table entry, claimed by the smallest corner (what a stable sort keeps
                        // first)
            keys[slot] = static_cast<uint64_t>(block) * edges_per_block + local_edge;
            atomic_min(&table[keys[slot]], static_cast<uint32_t>(slot));
          } else {
            keys[slot] = (static_cast<uint64_t>(block) << edge_bits) | local_edge;
          }
        }
        order[slot] = static_cast<uint32_t>(slot);
        const Vec3f p = marching_cubes::crossing_point(values, e);
        positions[slot] =
            Vec3f((origin.x + 0.5f + p.x) * voxel_size, (origin.y + 0.5f + p.y) * voxel_size,
                  (origin.z + 0.5f + p.z) * voxel_size);
        const float f = marching_cubes::crossing_fraction(values, e);
        const Rgb8 ca = colors[start], cb = colors[end];
        corner_colors[slot] = Rgb8{static_cast<uint8_t>(ca.r + f * (cb.r - ca.r) + 0.5f),
                                   static_cast<uint8_t>(ca.g + f * (cb.g - ca.g) + 0.5f),
                                   static_cast<uint8_t>(ca.b + f * (cb.b - ca.b) + 0.5f)};
      }
      ++t;
    });
  });

  if (weld_table) {
    // 3. weld through the table: claimed entries, in (block, local edge) order, are the
    //    vertices; the same numbering as the sorted keys below.
    scratch.flags.resize_discard(table_entries + 1);
    scratch.vertex_ids.resize_discard(table_entries + 1);
    uint32_t* claimed = scratch.flags.data();
    parallel_for(backend, stream, table_entries + 1, [=] COVOX_HD(int64_t e) {
      claimed[e] = e < table_entries && table[e] != kInvalidSlot ? 1u : 0u;
    });
    exclusive_scan(backend, stream, claimed, table_entries + 1, scratch.vertex_ids.data());
    const int64_t vertices = scratch.vertex_ids.element(table_entries, stream);
    const uint32_t* ids = scratch.vertex_ids.data();
    write_block_ranges(backend, stream, scratch, block_count, per_block, offsets,
                       TableFirstVertex{ids, edges_per_block});
    const uint32_t* block_first_vertex = scratch.block_first_vertex.data();
    const MeshOutputs out = size_outputs(scratch, vertices, corners);
    parallel_for(backend, stream, table_entries, [=] COVOX_HD(int64_t e) {
      if (!claimed[e]) return;
      out.vertices[ids[e]] = positions[table[e]];
      out.colors[ids[e]] = corner_colors[table[e]];
    });
    parallel_for(backend, stream, corners, [=] COVOX_HD(int64_t j) {
      out.triangles[j] = ids[keys[j]] - block_first_vertex[keys[j] / edges_per_block];
    });
    *vertex_count = vertices;
    return triangle_count;
  }

  // 3. weld: sort corners by edge, one vertex per distinct edge. Per-block keys need only
  //    bits_for(blocks) + 12 bits: a 3-4 pass radix sort instead of a full 64-bit one.
  if (per_block_weld) {
    scratch.keys_alt.resize_discard(corners);
    scratch.order_alt.resize_discard(corners);
    uint64_t* keys_alt = scratch.keys_alt.data();
    uint32_t* order_alt = scratch.order_alt.data();
    radix_sort_pairs_swapping(backend, stream, keys, order, corners,
                              bits_for(static_cast<uint64_t>(block_count)) + edge_bits, keys_alt,
                              order_alt);
  } else {
    sort_by_key(backend, stream, keys, order, corners);
  }
  scratch.flags.resize_discard(corners + 1);
  scratch.vertex_ids.resize_discard(corners + 1);
  uint32_t* flags = scratch.flags.data();
  parallel_for(backend, stream, corners + 1, [=] COVOX_HD(int64_t j) {
    flags[j] = (j < corners && (j == 0 || keys[j] != keys[j - 1])) ? 1u : 0u;
  });
  exclusive_scan(backend, stream, flags, corners + 1, scratch.vertex_ids.data());
  const int64_t vertices = scratch.vertex_ids.element(corners, stream);
  const uint32_t* first_ids = scratch.vertex_ids.data();
  const uint32_t* block_first_vertex = nullptr;
  if (per_block_weld) {
    write_block_ranges(backend, stream, scratch, block_count, per_block, offsets,
                       SortedFirstVertex{first_ids, keys, corners, edge_bits});
    block_first_vertex = scratch.block_first_vertex.data();
  }
  const MeshOutputs out = size_outputs(scratch, vertices, corners);
  parallel_for(backend, stream, corners, [=] COVOX_HD(int64_t j) {
    // The run of equal keys that j belongs to starts where the flag was set.
    const uint32_t id = first_ids[j] + flags[j] - 1;
    if (flags[j]) {
      out.vertices[id] = positions[order[j]];
      out.colors[id] = corner_colors[order[j]];
    }
    out.triangles[order[j]] =
        block_first_vertex ? id - block_first_vertex[keys[j] >> edge_bits] : id;
  });
  *vertex_count = vertices;
  return triangle_count;
}

template <class Backend>
int64_t mesh_select_blocks(Backend backend, TsdfMap& map, MeshScratchBuffers& scratch,
                           const Stream& stream) {
  const BlockHashTableView table = map.blocks().device_view();
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
    if (!is_live_block_key(key)) return;
    const uint32_t slot = table.slots[b];
    if (!(changed[slot] & kMeshPending)) return;
    changed[slot] = static_cast<uint8_t>(changed[slot] & ~kMeshPending);
    // A cube reads the block of its first corner and its +x/+y/+z neighbours, so a changed
    // block also changes the meshes of the seven blocks just below it.
    const Index3D block = unpack_block_key(key);
    for (int c = 0; c < 8; ++c) {
      const uint32_t below = table.slot_of(block - Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1));
      if (below != kInvalidSlot) atomic_add(&affected[below], 1u);
    }
  });
  // Compact to the affected blocks, in bucket order (each block's mesh depends only on the
  // block, not on this order).
  scratch.flags.resize_discard(buckets + 1);
  scratch.vertex_ids.resize_discard(buckets + 1);
  uint32_t* flags = scratch.flags.data();
  parallel_for(backend, stream, buckets + 1, [=] COVOX_HD(int64_t b) {
    flags[b] =
        b < buckets && is_live_block_key(table.keys[b]) && affected[table.slots[b]] > 0 ? 1u : 0u;
  });
  exclusive_scan(backend, stream, flags, buckets + 1, scratch.vertex_ids.data());
  const int64_t selected = scratch.vertex_ids.element(buckets, stream);
  scratch.blocks.resize_discard(selected);
  Index3D* blocks = scratch.blocks.data();
  const uint32_t* ranks = scratch.vertex_ids.data();
  parallel_for(backend, stream, buckets, [=] COVOX_HD(int64_t b) {
    if (flags[b]) blocks[ranks[b]] = unpack_block_key(table.keys[b]);
  });
  return selected;
}

#define COVOX_INSTANTIATE_MESH_INTEGRATOR(Backend)                                                \
  template int64_t mesh_extract<Backend>(Backend, TsdfMap&, float, MeshWeld, MeshScratchBuffers&, \
                                         int64_t*, const Stream&, int64_t);                       \
  template int64_t mesh_select_blocks<Backend>(Backend, TsdfMap&, MeshScratchBuffers&,            \
                                               const Stream&);

}  // namespace covox

#pragma once
// The ESDF update (see esdf_integrator.h), written once for both backends.
#include <thrust/iterator/counting_iterator.h>
#include <thrust/transform_reduce.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/core/parallel.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/map/block_voxel_indexer.h"

namespace covox::integrators {
namespace internal {

constexpr int32_t kFar = 0x7fffffff;  // no site on this line (squared distance "infinity")

// Inclusive bounds of a set of block indices, and how many there are.
struct BlockBounds {
  int32_t lo[3] = {0x7fffffff, 0x7fffffff, 0x7fffffff};
  int32_t hi[3] = {-0x7fffffff - 1, -0x7fffffff - 1, -0x7fffffff - 1};
  int64_t count = 0;
};
struct MergeBounds {
  COVOX_HD_INLINE BlockBounds operator()(const BlockBounds& a, const BlockBounds& b) const {
    BlockBounds m;
    for (int k = 0; k < 3; ++k) {
      m.lo[k] = a.lo[k] < b.lo[k] ? a.lo[k] : b.lo[k];
      m.hi[k] = a.hi[k] > b.hi[k] ? a.hi[k] : b.hi[k];
    }
    m.count = a.count + b.count;
    return m;
  }
};
// Bounds of the blocks that changed (or of all blocks when `all` is set).
struct BoundsOfBlock {
  const Index3D* indices;
  const uint32_t* slots;
  const uint8_t* changed;
  bool all;
  COVOX_HD_INLINE BlockBounds operator()(int64_t b) const {
    BlockBounds bounds;
    if (!all && !(changed[slots[b]] & map::kEsdfPending)) return bounds;
    const Index3D i = indices[b];
    bounds.lo[0] = bounds.hi[0] = i.x;
    bounds.lo[1] = bounds.hi[1] = i.y;
    bounds.lo[2] = bounds.hi[2] = i.z;
    bounds.count = 1;
    return bounds;
  }
};

// A box of voxels, inclusive.
struct VoxelBox {
  int32_t lo[3];
  int32_t hi[3];
  COVOX_HD_INLINE bool contains(const Index3D& v) const {
    return v.x >= lo[0] && v.x <= hi[0] && v.y >= lo[1] && v.y <= hi[1] && v.z >= lo[2] &&
           v.z <= hi[2];
  }
  // Index of voxel v in a dense array over the box, x fastest.
  COVOX_HD_INLINE int64_t offset_of(const Index3D& v) const {
    const int64_t size_x = static_cast<int64_t>(hi[0]) - lo[0] + 1,
                  size_y = static_cast<int64_t>(hi[1]) - lo[1] + 1;
    return (v.x - lo[0]) + size_x * ((v.y - lo[1]) + size_y * (v.z - lo[2]));
  }
  int64_t size(int axis) const { return static_cast<int64_t>(hi[axis]) - lo[axis] + 1; }
  int64_t volume() const { return size(0) * size(1) * size(2); }
};

// Exact 1-D squared distance transform of f along one line (Felzenszwalb & Huttenlocher):
// out[q] = min_p (q - p)^2 + f[p]. Entries equal to kFar take no part. `sites` and `bounds` are
// this line's scratch (n and n + 1 entries, stride `scratch_stride` apart so that neighbouring
// lines interleave and GPU threads read them coalesced).
COVOX_HD_INLINE void lower_envelope(const int32_t* f, int64_t f_stride, int32_t* out,
                                    int64_t out_stride, int32_t n, int32_t* sites, double* bounds,
                                    int64_t scratch_stride) {
  int32_t k = -1;
  for (int32_t q = 0; q < n; ++q) {
    const int32_t fq = f[q * f_stride];
    if (fq == kFar) continue;
    const double value_q = static_cast<double>(fq) + static_cast<double>(q) * q;
    while (k >= 0) {
      const int32_t v = sites[k * scratch_stride];
      const double value_v = static_cast<double>(f[v * f_stride]) + static_cast<double>(v) * v;
      const double s = (value_q - value_v) / (2.0 * (q - v));
      if (s > bounds[k * scratch_stride]) {
        ++k;
        sites[k * scratch_stride] = q;
        bounds[k * scratch_stride] = s;
        break;
      }
      --k;
    }
    if (k < 0) {
      k = 0;
      sites[0] = q;
      bounds[0] = -1.0e300;
    }
  }
  if (k < 0) {
    for (int32_t q = 0; q < n; ++q) out[q * out_stride] = kFar;
    return;
  }
  const int32_t last = k;
  k = 0;
  for (int32_t q = 0; q < n; ++q) {
    while (k < last && bounds[(k + 1) * scratch_stride] < q) ++k;
    const int32_t v = sites[k * scratch_stride];
    const int64_t d = static_cast<int64_t>(q - v) * (q - v) + f[v * f_stride];
    out[q * out_stride] = d > kFar ? kFar : static_cast<int32_t>(d);
  }
}

// The boxes of one update: the write region (changed blocks + halo) and the window the distance
// transform runs over (write region + halo), both clipped to the map's blocks (there are no
// sites and nothing to write beyond them). A site more than a halo outside the write region is
// farther than esdf_max_distance_m from every voxel written, so the window sees every site
// that matters.
struct UpdateBoxes {
  VoxelBox write_region;
  VoxelBox window;
};

inline UpdateBoxes update_boxes(const BlockBounds& changed, const BlockBounds& all, int32_t side,
                                int32_t halo) {
  UpdateBoxes boxes{};
  for (int k = 0; k < 3; ++k) {
    const int32_t map_lo = all.lo[k] * side, map_hi = (all.hi[k] + 1) * side - 1;
    boxes.write_region.lo[k] = std::max(map_lo, changed.lo[k] * side - halo);
    boxes.write_region.hi[k] = std::min(map_hi, (changed.hi[k] + 1) * side - 1 + halo);
    boxes.window.lo[k] = std::max(map_lo, boxes.write_region.lo[k] - halo);
    boxes.window.hi[k] = std::min(map_hi, boxes.write_region.hi[k] + halo);
  }
  return boxes;
}

inline void check_window_volume(int64_t volume, const EsdfIntegratorConfig& config) {
  if (volume > config.max_window_voxels) {
    throw Error("ESDF: the update window has " + std::to_string(volume) +
                " voxels, more than max_window_voxels (" +
                std::to_string(config.max_window_voxels) +
                "); update more often, or use larger voxels or a "
                "smaller esdf_max_distance_m");
  }
}

// The window's dense arrays: squared distances (and the transform's second copy), and the lower
// envelopes' per-line scratch, lines interleaved. `bounds` has one more entry per line than
// `sites`: wx max(wy, wz) lines at most.
struct WindowArrays {
  int32_t* squared;
  int32_t* squared_tmp;
  int32_t* sites;
  double* bounds;
  int32_t wx, wy, wz;
};

inline WindowArrays size_window_arrays(EsdfScratchBuffers& scratch, const VoxelBox& window) {
  const int64_t volume = window.volume();
  const int32_t wx = static_cast<int32_t>(window.size(0)),
                wy = static_cast<int32_t>(window.size(1)),
                wz = static_cast<int32_t>(window.size(2));
  scratch.squared.resize_discard(volume);
  scratch.squared_tmp.resize_discard(volume);
  scratch.envelope_sites.resize_discard(volume);
  scratch.envelope_bounds.resize_discard(volume + static_cast<int64_t>(wx) * std::max(wy, wz));
  return WindowArrays{scratch.squared.data(),
                      scratch.squared_tmp.data(),
                      scratch.envelope_sites.data(),
                      scratch.envelope_bounds.data(),
                      wx,
                      wy,
                      wz};
}

// The map's allocated blocks (exported: index and slot), walked voxel by voxel.
struct BlockVoxels {
  const Index3D* indices;
  const uint32_t* slots;
  int64_t voxels_per_block;
  int32_t side;
  // Voxel i of the walk: its global index and its index in the voxel pools.
  COVOX_HD_INLINE Index3D voxel(int64_t i, int64_t* pool_index) const {
    const int64_t b = i / voxels_per_block, k = i % voxels_per_block;
    *pool_index = static_cast<int64_t>(slots[b]) * voxels_per_block + k;
    return map::global_voxel(indices[b], k, side);
  }
};

// Kernel: no site anywhere yet.
struct FillFar {
  int32_t* squared;
  COVOX_HD_INLINE void operator()(int64_t i) const { squared[i] = kFar; }
};

// Kernel: sites are the window's observed voxels close to the surface (squared distance 0).
struct MarkSites {
  BlockVoxels walk;
  map::TsdfMap::TsdfStorage::View tsdf;
  VoxelBox window;
  int32_t* squared;
  float site_threshold_m;
  float min_weight;
  COVOX_HD_INLINE void operator()(int64_t i) const {
    int64_t index;
    const Index3D v = walk.voxel(i, &index);
    if (!window.contains(v)) return;
    const map::TsdfVoxel voxel = tsdf.load(index);
    if (voxel.weight >= min_weight && fabsf(voxel.distance_m) <= site_threshold_m)
      squared[window.offset_of(v)] = 0;
  }
};

// Kernel: per x row, the squared distance to the nearest site in the row (two sweeps).
struct RowDistances {
  int32_t* squared;
  int32_t wx;
  COVOX_HD_INLINE void operator()(int64_t line) const {
    int32_t* row = squared + line * wx;
    int32_t last_site = -1;
    for (int32_t x = 0; x < wx; ++x) {
      if (row[x] == 0) last_site = x;
      row[x] = last_site < 0 ? kFar : x - last_site;
    }
    int32_t next_site = -1;
    for (int32_t x = wx - 1; x >= 0; --x) {
      if (row[x] == 0) next_site = x;
      int32_t d = row[x];
      if (next_site >= 0 && next_site - x < d) d = next_site - x;
      row[x] = d == kFar ? kFar : d * d;
    }
  }
};

// Kernel: lower envelopes along y over the x result, from `squared` into `squared_tmp` (lines
// indexed by x fastest: coalesced on the GPU).
struct EnvelopesAlongY {
  WindowArrays a;
  COVOX_HD_INLINE void operator()(int64_t line) const {
    const int64_t y_lines = static_cast<int64_t>(a.wx) * a.wz;
    const int64_t x = line % a.wx, z = line / a.wx;
    const int64_t base = x + static_cast<int64_t>(a.wx) * a.wy * z;
    lower_envelope(a.squared + base, a.wx, a.squared_tmp + base, a.wx, a.wy, a.sites + line,
                   a.bounds + line, y_lines);
  }
};

// Kernel: lower envelopes along z over the y result, from `squared_tmp` back into `squared`.
struct EnvelopesAlongZ {
  WindowArrays a;
  COVOX_HD_INLINE void operator()(int64_t line) const {
    const int64_t z_lines = static_cast<int64_t>(a.wx) * a.wy;
    lower_envelope(a.squared_tmp + line, z_lines, a.squared + line, z_lines, a.wz, a.sites + line,
                   a.bounds + line, z_lines);
  }
};

// Kernel: the write region's voxels get the distance, signed by the TSDF and clamped to the
// maximum; unobserved voxels are stored as unobserved.
struct WriteDistances {
  BlockVoxels walk;
  map::TsdfMap::TsdfStorage::View tsdf;
  map::TsdfMap::EsdfStorage::View esdf;
  VoxelBox write_region;
  VoxelBox window;
  const int32_t* squared;
  float min_weight;
  float max_distance_m;
  float voxel_size_m;
  COVOX_HD_INLINE void operator()(int64_t i) const {
    int64_t index;
    const Index3D v = walk.voxel(i, &index);
    if (!write_region.contains(v)) return;
    const map::TsdfVoxel voxel = tsdf.load(index);
    map::EsdfVoxel out;
    out.observed = voxel.weight >= min_weight ? 1 : 0;
    if (out.observed) {
      const int32_t d2 = squared[window.offset_of(v)];
      float distance = d2 == kFar ? max_distance_m : sqrtf(static_cast<float>(d2)) * voxel_size_m;
      distance = distance < max_distance_m ? distance : max_distance_m;
      out.is_site = d2 == 0 ? 1 : 0;
      out.distance_m = voxel.distance_m < 0.0f ? -distance : distance;
    }
    esdf.store(index, out);
  }
};

// Kernel: clears a block's kEsdfPending bit.
struct ClearEsdfPending {
  const uint32_t* slots;
  uint8_t* changed;
  COVOX_HD_INLINE void operator()(int64_t b) const {
    changed[slots[b]] &= static_cast<uint8_t>(~map::kEsdfPending);
  }
};

// Bounds of the exported blocks whose ESDF is pending (of all of them when `all` is set).
template <class Backend>
BlockBounds reduce_block_bounds(Backend backend, const Stream& stream,
                                const EsdfScratchBuffers& scratch, const uint8_t* changed,
                                bool all) {
  return thrust::transform_reduce(
      execution_policy(backend, stream), thrust::counting_iterator<int64_t>(0),
      thrust::counting_iterator<int64_t>(static_cast<int64_t>(scratch.block_indices.size())),
      BoundsOfBlock{scratch.block_indices.data(), scratch.block_slots.data(), changed, all},
      BlockBounds{}, MergeBounds{});
}

// The exact Euclidean distance transform over the window: per-row distances along x, then
// lower envelopes along y and along z; the result ends in `squared`.
template <class Backend>
void distance_transform(Backend backend, const Stream& stream, const WindowArrays& arrays) {
  parallel_for(backend, stream, static_cast<int64_t>(arrays.wy) * arrays.wz,
               RowDistances{arrays.squared, arrays.wx});
  parallel_for(backend, stream, static_cast<int64_t>(arrays.wx) * arrays.wz,
               EnvelopesAlongY{arrays});
  parallel_for(backend, stream, static_cast<int64_t>(arrays.wx) * arrays.wy,
               EnvelopesAlongZ{arrays});
}

}  // namespace internal

template <class Backend>
EsdfUpdateStats esdf_update(Backend backend, const EsdfIntegratorConfig& config, map::TsdfMap& map,
                            bool all_blocks, EsdfScratchBuffers& scratch, const Stream& stream) {
  using namespace internal;
  EsdfUpdateStats stats;
  map.blocks().export_entries(&scratch.block_indices, &scratch.block_slots);
  const int64_t block_count = static_cast<int64_t>(scratch.block_indices.size());
  if (block_count == 0) return stats;
  uint8_t* changed = map.block_changed().data();
  const BlockBounds changed_bounds =
      reduce_block_bounds(backend, stream, scratch, changed, all_blocks);
  stats.changed_blocks = changed_bounds.count;
  if (changed_bounds.count == 0) return stats;
  const BlockBounds all_bounds = reduce_block_bounds(backend, stream, scratch, changed, true);

  const int32_t side = map.voxels_per_side();
  const float voxel_size = map.voxel_size_m();
  const int32_t halo = static_cast<int32_t>(std::ceil(config.esdf_max_distance_m / voxel_size));
  const UpdateBoxes boxes = update_boxes(changed_bounds, all_bounds, side, halo);
  const int64_t volume = boxes.window.volume();
  check_window_volume(volume, config);
  stats.window_voxels = volume;
  const WindowArrays arrays = size_window_arrays(scratch, boxes.window);

  const BlockVoxels walk{scratch.block_indices.data(), scratch.block_slots.data(),
                         map.voxels_per_block(), side};
  const int64_t voxels = block_count * walk.voxels_per_block;
  const auto tsdf = map.tsdf().view();
  parallel_for(backend, stream, volume, FillFar{arrays.squared});
  parallel_for(backend, stream, voxels,
               MarkSites{walk, tsdf, boxes.window, arrays.squared,
                         config.site_distance_threshold_vox * voxel_size, config.min_weight});
  distance_transform(backend, stream, arrays);
  parallel_for(
      backend, stream, voxels,
      WriteDistances{walk, tsdf, map.esdf().view(), boxes.write_region, boxes.window,
                     arrays.squared, config.min_weight, config.esdf_max_distance_m, voxel_size});
  stats.voxels_written = boxes.write_region.volume();
  // Every changed block lies inside the write region: all caught up.
  parallel_for(backend, stream, block_count, ClearEsdfPending{walk.slots, changed});
  stream.synchronize();
  return stats;
}

#define COVOX_INSTANTIATE_ESDF_INTEGRATOR(Backend)                                        \
  template EsdfUpdateStats esdf_update<Backend>(Backend, const EsdfIntegratorConfig&,     \
                                                map::TsdfMap&, bool, EsdfScratchBuffers&, \
                                                const Stream&);

}  // namespace covox::integrators

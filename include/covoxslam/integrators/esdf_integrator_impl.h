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

namespace covox {
namespace esdf_detail {

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
    if (!all && !(changed[slots[b]] & kEsdfPending)) return bounds;
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

}  // namespace esdf_detail

template <class Backend>
EsdfUpdateStats esdf_update(Backend backend, const EsdfIntegratorConfig& config, TsdfMap& map,
                            bool all_blocks, EsdfScratchBuffers& scratch, const Stream& stream) {
  using namespace esdf_detail;
  EsdfUpdateStats stats;
  map.blocks().export_entries(&scratch.block_indices, &scratch.block_slots);
  const int64_t block_count = static_cast<int64_t>(scratch.block_indices.size());
  if (block_count == 0) return stats;
  const Index3D* block_indices = scratch.block_indices.data();
  const uint32_t* block_slots = scratch.block_slots.data();
  uint8_t* changed = map.block_changed().data();

  const auto policy = execution_policy(backend, stream);
  const BlockBounds changed_bounds = thrust::transform_reduce(
      policy, thrust::counting_iterator<int64_t>(0),
      thrust::counting_iterator<int64_t>(block_count),
      BoundsOfBlock{block_indices, block_slots, changed, all_blocks}, BlockBounds{}, MergeBounds{});
  stats.changed_blocks = changed_bounds.count;
  if (changed_bounds.count == 0) return stats;
  const BlockBounds all_bounds = thrust::transform_reduce(
      policy, thrust::counting_iterator<int64_t>(0),
      thrust::counting_iterator<int64_t>(block_count),
      BoundsOfBlock{block_indices, block_slots, changed, true}, BlockBounds{}, MergeBounds{});

  // Voxel boxes: write region = changed blocks + halo; window = write region + halo, both
  // clipped to the map's blocks (there are no sites and nothing to write beyond them).
  const int32_t side = map.voxels_per_side();
  const float voxel_size = map.voxel_size_m();
  const int32_t halo = static_cast<int32_t>(std::ceil(config.esdf_max_distance_m / voxel_size));
  VoxelBox write_region{}, window{};
  for (int k = 0; k < 3; ++k) {
    const int32_t map_lo = all_bounds.lo[k] * side, map_hi = (all_bounds.hi[k] + 1) * side - 1;
    write_region.lo[k] = std::max(map_lo, changed_bounds.lo[k] * side - halo);
    write_region.hi[k] = std::min(map_hi, (changed_bounds.hi[k] + 1) * side - 1 + halo);
    window.lo[k] = std::max(map_lo, write_region.lo[k] - halo);
    window.hi[k] = std::min(map_hi, write_region.hi[k] + halo);
  }
  const int64_t volume = window.volume();
  if (volume > config.max_window_voxels) {
    throw Error("ESDF: the update window has " + std::to_string(volume) +
                " voxels, more than max_window_voxels (" +
                std::to_string(config.max_window_voxels) +
                "); update more often, or use larger voxels or a "
                "smaller esdf_max_distance_m");
  }
  stats.window_voxels = volume;
  const int32_t wx = static_cast<int32_t>(window.size(0)),
                wy = static_cast<int32_t>(window.size(1)),
                wz = static_cast<int32_t>(window.size(2));
  scratch.squared.resize_discard(volume);
  scratch.squared_tmp.resize_discard(volume);
  scratch.envelope_sites.resize_discard(volume);
  scratch.envelope_bounds.resize_discard(volume + static_cast<int64_t>(wx) * std::max(wy, wz));
  int32_t* squared = scratch.squared.data();
  int32_t* squared_tmp = scratch.squared_tmp.data();
  int32_t* envelope_sites = scratch.envelope_sites.data();
  double* envelope_bounds = scratch.envelope_bounds.data();

  // Sites: observed voxels close to the surface.
  parallel_for(backend, stream, volume, [=] COVOX_HD(int64_t i) { squared[i] = kFar; });
  const int64_t voxels_per_block = map.voxels_per_block();
  const auto tsdf = map.tsdf().view();
  const float site_threshold = config.site_distance_threshold_vox * voxel_size;
  const float min_weight = config.min_weight;
  parallel_for(backend, stream, block_count * voxels_per_block, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / voxels_per_block, k = i % voxels_per_block;
    const Index3D v = global_voxel(block_indices[b], k, side);
    if (!window.contains(v)) return;
    const TsdfVoxel voxel = tsdf.load(static_cast<int64_t>(block_slots[b]) * voxels_per_block + k);
    if (voxel.weight >= min_weight && fabsf(voxel.distance_m) <= site_threshold)
      squared[window.offset_of(v)] = 0;
  });

  // x: distance to the nearest site in the row (two sweeps), squared.
  parallel_for(backend, stream, static_cast<int64_t>(wy) * wz, [=] COVOX_HD(int64_t line) {
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
  });
  // y: lower envelopes over the x result (lines indexed by x fastest: coalesced on the GPU).
  const int64_t y_lines = static_cast<int64_t>(wx) * wz;
  parallel_for(backend, stream, y_lines, [=] COVOX_HD(int64_t line) {
    const int64_t x = line % wx, z = line / wx;
    const int64_t base = x + static_cast<int64_t>(wx) * wy * z;
    lower_envelope(squared + base, wx, squared_tmp + base, wx, wy, envelope_sites + line,
                   envelope_bounds + line, y_lines);
  });
  // z: lower envelopes over the y result.
  const int64_t z_lines = static_cast<int64_t>(wx) * wy;
  parallel_for(backend, stream, z_lines, [=] COVOX_HD(int64_t line) {
    lower_envelope(squared_tmp + line, z_lines, squared + line, z_lines, wz, envelope_sites + line,
                   envelope_bounds + line, z_lines);
  });

  // Write back the voxels of the write region, signed by the TSDF, clamped to the maximum.
  const auto esdf = map.esdf().view();
  const float max_distance = config.esdf_max_distance_m;
  parallel_for(backend, stream, block_count * voxels_per_block, [=] COVOX_HD(int64_t i) {
    const int64_t b = i / voxels_per_block, k = i % voxels_per_block;
    const Index3D v = global_voxel(block_indices[b], k, side);
    if (!write_region.contains(v)) return;
    const int64_t index = static_cast<int64_t>(block_slots[b]) * voxels_per_block + k;
    const TsdfVoxel voxel = tsdf.load(index);
    EsdfVoxel out;
    out.observed = voxel.weight >= min_weight ? 1 : 0;
    if (out.observed) {
      const int32_t d2 = squared[window.offset_of(v)];
      float distance = d2 == kFar ? max_distance : sqrtf(static_cast<float>(d2)) * voxel_size;
      distance = distance < max_distance ? distance : max_distance;
      out.is_site = d2 == 0 ? 1 : 0;
      out.distance_m = voxel.distance_m < 0.0f ? -distance : distance;
    }
    esdf.store(index, out);
  });
  stats.voxels_written = write_region.volume();
  // Every changed block lies inside the write region: all caught up.
  parallel_for(backend, stream, block_count, [=] COVOX_HD(int64_t b) {
    changed[block_slots[b]] &= static_cast<uint8_t>(~kEsdfPending);
  });
  stream.synchronize();
  return stats;
}

#define COVOX_INSTANTIATE_ESDF_INTEGRATOR(Backend)                                              \
  template EsdfUpdateStats esdf_update<Backend>(Backend, const EsdfIntegratorConfig&, TsdfMap&, \
                                                bool, EsdfScratchBuffers&, const Stream&);

}  // namespace covox

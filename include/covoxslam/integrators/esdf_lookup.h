#pragma once
// The device-side ESDF lookup: a TsdfMap's ESDF voxels read by global voxel index from a kernel of
// either backend, one voxel or trilinear at a point. The ESDF queries use it, and so does dense
// registration (backend), whose residuals sample a submap's distance field inside its own kernels.
#include <cmath>
#include <cstdint>

#include "covoxslam/core/macros.h"
#include "covoxslam/core/soa_container.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/esdf_queries.h"
#include "covoxslam/map/block_voxel_indexer.h"
#include "covoxslam/map/voxels.h"

namespace covox::integrators {

// What a kernel needs to look a voxel up by its global index.
struct EsdfLookup {
  map::BlockVoxelIndexer indexer;
  VoxelView<map::EsdfVoxel, Layout::kSoA> esdf;
  float voxel_size;

  // Returns false for unallocated or unobserved voxels.
  COVOX_HD_INLINE bool voxel(const Index3D& v, float* distance) const {
    const int64_t index = indexer.pool_index(v);
    if (index < 0 || !esdf.get<&map::EsdfVoxel::observed>(index)) return false;
    *distance = esdf.get<&map::EsdfVoxel::distance_m>(index);
    return true;
  }

  COVOX_HD_INLINE EsdfSample sample(const Vec3f& p) const {
    EsdfSample out;
    // Voxel centres sit at (i + 0.5) * voxel_size: interpolate between the 8 around p.
    const float gx = p.x / voxel_size - 0.5f, gy = p.y / voxel_size - 0.5f,
                gz = p.z / voxel_size - 0.5f;
    const Index3D base(static_cast<int32_t>(floorf(gx)), static_cast<int32_t>(floorf(gy)),
                       static_cast<int32_t>(floorf(gz)));
    const float fx = gx - base.x, fy = gy - base.y, fz = gz - base.z;
    float d[8];
    for (int c = 0; c < 8; ++c) {
      if (!voxel(base + Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1), &d[c])) return out;
    }
    const float x00 = d[0] + fx * (d[1] - d[0]), x10 = d[2] + fx * (d[3] - d[2]);
    const float x01 = d[4] + fx * (d[5] - d[4]), x11 = d[6] + fx * (d[7] - d[6]);
    const float y0 = x00 + fy * (x10 - x00), y1 = x01 + fy * (x11 - x01);
    out.distance_m = y0 + fz * (y1 - y0);
    // Derivatives of the trilinear form, divided by the voxel size for metres.
    const float ddx = (1 - fz) * ((1 - fy) * (d[1] - d[0]) + fy * (d[3] - d[2])) +
                      fz * ((1 - fy) * (d[5] - d[4]) + fy * (d[7] - d[6]));
    const float ddy = (1 - fz) * (x10 - x00) + fz * (x11 - x01);
    const float ddz = y1 - y0;
    out.gradient = Vec3f(ddx / voxel_size, ddy / voxel_size, ddz / voxel_size);
    out.valid = 1;
    return out;
  }
};

}  // namespace covox::integrators

#pragma once
// A TSDF frame's tally of its points and rays: points per kind, rays cast, the total voxel count
// and the box of voxels the rays traverse, in one reduction (one read-back). The box sizes the
// frame's update keys; the rest steers the frame's plan (tsdf_frame_plan.h).
#include <climits>
#include <cstdint>

#include "covoxslam/core/index3d.h"
#include "covoxslam/core/macros.h"
#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox::integrators::tsdf {

struct RayTally {
  int64_t kinds[6] = {0, 0, 0, 0, 0, 0};  // input points, by what became of them
  int64_t cast = 0;                       // surface and clearing rays (after merging)
  int64_t rays = 0;                       // merged rays, of every kind
  int64_t voxels = 0;
  int32_t most_pieces = 0;  // the longest ray's pieces: the ray groups' levels (tsdf_traverse.h)
  int32_t low[3] = {INT32_MAX, INT32_MAX, INT32_MAX};
  int32_t high[3] = {INT32_MIN, INT32_MIN, INT32_MIN};

  Index3D low_voxel() const { return Index3D(low[0], low[1], low[2]); }
  Index3D high_voxel() const { return Index3D(high[0], high[1], high[2]); }
};

// The tally of one ray that stands for `points` input points (a merged bundle's count; 1 without
// merging).
COVOX_HD_INLINE RayTally tally_ray(const RaySegment& ray, int64_t points,
                                   float inverse_voxel_size) {
  RayTally tally;
  // (each kind by a constant index: an index by ray.kind puts the tally in local memory on the GPU)
  for (int k = 0; k < 6; ++k) tally.kinds[k] = ray.kind == k ? points : 0;
  tally.cast = ray.kind <= kClearingRay ? 1 : 0;
  tally.voxels = ray_voxel_count(ray, inverse_voxel_size);
  tally.most_pieces = static_cast<int32_t>(ray_piece_count(static_cast<uint32_t>(tally.voxels)));
  if (ray.kind <= kClearingRay) {  // a segment's voxels lie in the box of its end voxels
    const Index3D a = voxel_of(ray.start, inverse_voxel_size);
    const Index3D b = voxel_of(ray.end, inverse_voxel_size);
    const int32_t av[3] = {a.x, a.y, a.z}, bv[3] = {b.x, b.y, b.z};
    for (int axis = 0; axis < 3; ++axis) {
      tally.low[axis] = av[axis] < bv[axis] ? av[axis] : bv[axis];
      tally.high[axis] = av[axis] > bv[axis] ? av[axis] : bv[axis];
    }
  }
  return tally;
}

struct AddTallies {
  COVOX_HD_INLINE RayTally operator()(const RayTally& a, const RayTally& b) const {
    RayTally sum;
    for (int k = 0; k < 6; ++k) sum.kinds[k] = a.kinds[k] + b.kinds[k];
    sum.cast = a.cast + b.cast;
    sum.rays = a.rays + b.rays;
    sum.voxels = a.voxels + b.voxels;
    sum.most_pieces = a.most_pieces > b.most_pieces ? a.most_pieces : b.most_pieces;
    for (int axis = 0; axis < 3; ++axis) {
      sum.low[axis] = a.low[axis] < b.low[axis] ? a.low[axis] : b.low[axis];
      sum.high[axis] = a.high[axis] > b.high[axis] ? a.high[axis] : b.high[axis];
    }
    return sum;
  }
};

}  // namespace covox::integrators::tsdf

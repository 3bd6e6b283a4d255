#pragma once
// Reading the ESDF of a TsdfMap: distances and gradients at arbitrary points (trilinear, in
// batches on the device), and 2-D slices for planners and rviz.
#include <cstdint>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox::integrators {

// One query answer. `valid` is 0 when one of the 8 voxels around the point is unobserved or
// unallocated: then distance and gradient mean nothing.
struct EsdfSample {
  float distance_m = 0.0f;
  Vec3f gradient;  // d distance / d position (unitless, about unit length away from sites)
  uint8_t valid = 0;
};

// Trilinear distance and its gradient at `count` points (device memory of the map's device).
void query_esdf(const map::TsdfMap& map, const Vec3f* points_m, int64_t count, EsdfSample* samples,
                const Stream& stream);
// Host convenience.
std::vector<EsdfSample> query_esdf(const map::TsdfMap& map, const std::vector<Vec3f>& points_m);

// A point of a slice: the centre of a voxel column (x, y), the slice height, and the distance.
struct SlicePoint {
  Vec3f position_m;
  float distance_m = 0.0f;
};

// Every observed voxel of the layer holding height z_m.
std::vector<SlicePoint> esdf_slice(const map::TsdfMap& map, float z_m, const Stream& stream);
// For every (x, y) column with an observed voxel in [z_min_m, z_max_m], the smallest distance in
// that band (a 2-D map for a ground robot or a drone at a fixed height band), reported at
// height (z_min_m + z_max_m) / 2.
std::vector<SlicePoint> esdf_squashed_slice(const map::TsdfMap& map, float z_min_m, float z_max_m,
                                            const Stream& stream);

// Every observed voxel whose distance is at most max_distance_m (obstacles and the free space
// near them; negative distances lie inside surfaces), at its centre in the map's frame: the 3-D
// ESDF a planner subscribes to.
std::vector<SlicePoint> esdf_voxels_within(const map::TsdfMap& map, float max_distance_m,
                                           const Stream& stream);

}  // namespace covox::integrators

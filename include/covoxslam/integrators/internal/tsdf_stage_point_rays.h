#pragma once
// Stage 1 of a TSDF frame with the simple method: one ray per point, and the frame's tally. A
// depth image is unprojected first (UnprojectPixels).
#include <cstdint>

#include "covoxslam/core/parallel.h"
#include "covoxslam/integrators/internal/tsdf_frame_plan.h"
#include "covoxslam/integrators/internal/tsdf_ray_tally.h"

namespace covox::integrators::tsdf {

// One thread per place in tile order: the stores are contiguous, the reads 32 pixels of a tile.
struct UnprojectPixels {
  DepthImagePoints image;
  Vec3f* points;
  Rgb8* colors;
  COVOX_HD_INLINE void operator()(int64_t place) const {
    const int64_t pixel = image.pixel_at(place);
    points[place] = image.point(pixel);
    if (colors) colors[place] = image.colors[pixel];
  }
};

// Writes the image's points (and colours) into scratch.input, in tile order.
template <class Backend>
void unproject_depth(Backend backend, const DepthImagePoints& image,
                     TsdfScratchBuffers::Input& input, const Stream& stream) {
  const int64_t pixels = image.pixels();
  input.points.resize_discard(pixels);
  Rgb8* colors = nullptr;
  if (image.colors) {
    input.colors.resize_discard(pixels);
    colors = input.colors.data();
  }
  parallel_for(backend, stream, pixels, UnprojectPixels{image, input.points.data(), colors});
}

// The tally of a point's own ray, computed from the point (no ray array written).
struct TallyPoint {
  RayParameters ray_parameters;
  float inverse_voxel_size;
  COVOX_HD_INLINE RayTally operator()(const Vec3f& point) const {
    return tally_ray(make_ray(ray_parameters, point), 1, inverse_voxel_size);
  }
};

// Each point's ray and its piece count; thread n writes the counts' end (for the scan).
struct WritePointRays {
  RayParameters ray_parameters;
  float inverse_voxel_size;
  const Vec3f* points;
  int64_t n;
  RaySegment* rays;
  uint32_t* ray_pieces;
  COVOX_HD_INLINE void operator()(int64_t i) const {
    if (i == n) {
      ray_pieces[n] = 0;  // the scan's end
      return;
    }
    const RaySegment ray = make_ray(ray_parameters, points[i]);
    rays[i] = ray;
    ray_pieces[i] = ray_piece_count(ray_voxel_count(ray, inverse_voxel_size));
  }
};

// Stage 1 (simple method): the frame's rays and tally.
template <class Backend>
FrameRays point_rays(const FrameContext<Backend>& frame, const FramePoints& points,
                     const RayParameters& ray_parameters) {
  TsdfScratchBuffers& scratch = frame.scratch;
  const int64_t n = points.cloud.count;
  const float inverse_voxel_size = 1.0f / ray_parameters.voxel_size_m;
  if (points.depth_image) {
    unproject_depth(frame.backend, *points.depth_image, scratch.input, frame.stream);
    frame.profile.mark("1 rays: unproject depth");
  }
  FrameRays rays;
  // Why points did or did not become rays, and the box of voxels their own rays traverse.
  rays.tally =
      transform_reduce(frame.backend, frame.stream, points.cloud.points, n,
                       TallyPoint{ray_parameters, inverse_voxel_size}, RayTally{}, AddTallies{});
  frame.profile.mark("1 rays: per point + tally");
  scratch.rays.rays.resize_discard(n);
  scratch.rays.pieces.resize_discard(n + 1);
  parallel_for(frame.backend, frame.stream, n + 1,
               WritePointRays{ray_parameters, inverse_voxel_size, points.cloud.points, n,
                              scratch.rays.rays.data(), scratch.rays.pieces.data()});
  rays.count = n;
  rays.rays = scratch.rays.rays.data();
  rays.pieces = scratch.rays.pieces.data();
  rays.colors = points.colors;
  rays.intensities = points.intensities;
  rays.grey_per_intensity = points.grey_per_intensity;
  return rays;
}

}  // namespace covox::integrators::tsdf

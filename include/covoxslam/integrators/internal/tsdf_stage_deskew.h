#pragma once
// Stage 0 of a TSDF frame from a timed cloud: every point moved into the sensor frame at the
// cloud's pose by its time (sweep_motion.h), written to scratch; the later stages read the
// moved points through the frame's view as they would read the caller's.
#include <cstdint>

#include "covoxslam/core/parallel.h"
#include "covoxslam/integrators/internal/tsdf_frame_plan.h"
#include "covoxslam/integrators/internal/tsdf_scratch.h"

namespace covox::integrators::tsdf {

struct DeskewPoints {
  const Vec3f* points;
  const float* times_s;
  SweepMotion sweep;
  Vec3f* deskewed;
  COVOX_HD_INLINE void operator()(int64_t i) const {
    deskewed[i] = sweep.deskew(points[i], times_s[i]);
  }
};

// `points` with its cloud's points de-skewed into scratch (and its times consumed).
template <class Backend>
FramePoints deskew_points(Backend backend, const FramePoints& points,
                          TsdfScratchBuffers::Input& input, const Stream& stream) {
  const int64_t n = points.cloud.count;
  input.deskewed_points.resize_discard(n);
  parallel_for(backend, stream, n,
               DeskewPoints{points.cloud.points, points.cloud.times_s, points.cloud.sweep,
                            input.deskewed_points.data()});
  FramePoints moved = points;
  moved.cloud.points = input.deskewed_points.data();
  moved.cloud.times_s = nullptr;
  return moved;
}

}  // namespace covox::integrators::tsdf

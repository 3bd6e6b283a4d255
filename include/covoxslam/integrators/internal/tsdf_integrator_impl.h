#pragma once
// A TSDF frame, written once for both backends: the stages 0 de-skew, 1 rays, 2 walk, 3 group,
// 4 blocks and 5 write, each in a tsdf_stage_*.h header of its own, steered by the frame's plan
// (tsdf_frame_plan.h). The profiler's labels (COVOX_PROFILE_STAGES) carry the same numbers and
// names; docs/design.md ("TSDF integration") describes the stages.
#include <cstdint>

#include <Eigen/Geometry>

#include "covoxslam/core/eigen_conversions.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/integrators/internal/tsdf_frame_plan.h"
#include "covoxslam/integrators/internal/tsdf_stage_blocks.h"
#include "covoxslam/integrators/internal/tsdf_stage_deskew.h"
#include "covoxslam/integrators/internal/tsdf_stage_finish.h"
#include "covoxslam/integrators/internal/tsdf_stage_group_records.h"
#include "covoxslam/integrators/internal/tsdf_stage_merge_rays.h"
#include "covoxslam/integrators/internal/tsdf_stage_point_rays.h"
#include "covoxslam/integrators/internal/tsdf_stage_ray_pieces.h"
#include "covoxslam/integrators/internal/tsdf_stage_walk_visits.h"
#include "covoxslam/integrators/internal/tsdf_stage_write_voxels.h"
#include "covoxslam/integrators/internal/tsdf_integrator_ops.h"

namespace covox::integrators {
namespace tsdf {

// Stages 2b walk, 3 group, 4 blocks and 5 write with the frame's record types: KeyT 32-bit when the
// frame's box allows (almost always: half the key bytes through the walk's writes, every radix pass
// and the reduction); ValueT tsdf::DistanceUpdate without colour, summed as it is, tsdf::ColorVisit
// with colour, whose update is computed from its ray and voxel as the sum reads it
// (tsdf_traverse.h).
template <class KeyT, class ValueT, class Backend>
void fuse_visits(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                 const FrameUpdates& updates, IntegrationStats* stats) {
  FrameRecords<KeyT, ValueT> records = prepare_records<KeyT, ValueT>(frame, plan);
  walk_visits(frame, plan, updates, &records);
  frame.profile.mark("2b walk: traverse");
  stats->records_grouped = records.record_count;
  if (plan.groups_on_cpu) {
    group_records_on_cpu(frame, plan, updates, &records);
    frame.profile.mark("3 group: by block (CPU)");
  }
  BlockListing listing;
  prepare_block_listing(frame, plan, records, &listing);
  const PendingActivationGuard activation_guard(
      frame.map.blocks(), &frame.scratch.results.data()->new_blocks, frame.stream);
  if (plan.marks_blocks) {  // before the sort, which then hides the wait for the activation
    list_marked_blocks(frame, plan, records, &listing);
    frame.profile.mark("4a blocks: list marked, activate");
  }
  if (!records.grouped && !plan.sums_every_visit()) {
    sort_records(frame, plan, &records);
    frame.profile.mark("3 group: sort records");
  }
  if (!plan.marks_blocks) {
    list_sorted_blocks(frame, plan, records, &listing);
    frame.profile.mark("4a blocks: list sorted, activate");
  }
  stats->blocks_allocated = finish_activation(frame, plan, &listing);
  if (!plan.sums_every_visit()) clear_new_blocks(frame, listing);
  frame.profile.mark("4d blocks: clear new");
  if (!plan.sums_every_visit()) {
    write_record_voxels(frame, plan, updates, records, listing);
    frame.profile.mark("5a write: record runs");
  }
  if (plan.sums_visits()) {
    write_summed_cells(frame, plan, records, listing);
    frame.profile.mark("5b write: listed cells");
  }
  reset_merge_tally(frame.backend, frame.scratch.merge, frame.stream);  // for the next frame
  stats->blocks_allocated = read_frame_end(frame, plan, records, &listing);
  count_frame_voxels(frame, plan, records, listing, stats);
  frame.profile.mark("5c write: frame end");
}

template <class Backend>
void fuse_frame(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                const FrameUpdates& updates, IntegrationStats* stats) {
  if (plan.has_color && plan.short_keys) {
    fuse_visits<uint32_t, ColorVisit>(frame, plan, updates, stats);
  } else if (plan.has_color) {
    fuse_visits<uint64_t, ColorVisit>(frame, plan, updates, stats);
  } else if (plan.short_keys) {
    fuse_visits<uint32_t, DistanceUpdate>(frame, plan, updates, stats);
  } else {
    fuse_visits<uint64_t, DistanceUpdate>(frame, plan, updates, stats);
  }
}

// Why points did or did not become rays.
inline void count_rays(const RayTally& tally, IntegrationStats* stats) {
  stats->surface_rays = tally.kinds[kSurfaceRay];
  stats->clearing_rays = tally.kinds[kClearingRay];
  stats->dropped_non_finite = tally.kinds[kDroppedNonFinite];
  stats->dropped_zero = tally.kinds[kDroppedZero];
  stats->dropped_too_close = tally.kinds[kDroppedTooClose];
  stats->dropped_too_far = tally.kinds[kDroppedTooFar];
  stats->rays_cast = tally.cast;
  stats->voxel_updates = tally.voxels;
}

inline RayParameters ray_parameters_of(const TsdfIntegratorConfig& config, float voxel_size,
                                       const Eigen::Isometry3d& T_map_sensor) {
  return RayParameters{to_transform3f(T_map_sensor),
                       voxel_size,
                       config.truncation_distance_m,
                       config.min_ray_length_m,
                       config.max_ray_length_m,
                       config.voxel_carving_enabled,
                       config.allow_clear};
}
inline WeightParameters weight_parameters_of(const TsdfIntegratorConfig& config, float voxel_size) {
  return WeightParameters{voxel_size,
                          config.truncation_distance_m,
                          config.use_const_weight,
                          config.use_weight_dropoff,
                          config.use_sparsity_compensation_factor,
                          config.sparsity_compensation_factor};
}

// A frame: a timed cloud's points de-skewed (stage 0 de-skew), its rays and tally (stage 1 rays),
// its plan, how its visits are walked (stage 2a), then stages 2b to 5 (fuse_visits).
template <class Backend>
IntegrationStats integrate_frame(Backend backend, const TsdfIntegratorConfig& config,
                                 const FrameStrategy& strategy, map::TsdfMap& map,
                                 const FramePoints& input, const Eigen::Isometry3d& T_map_sensor,
                                 TsdfScratchBuffers& scratch, const Stream& stream) {
  IntegrationStats stats;
  stats.points_in = input.cloud.count;
  if (input.cloud.count == 0) return stats;
  StageProfiler::Scope profile("tsdf", stream);
  const FrameContext<Backend> frame{backend, stream, config, map, scratch, profile};
  const bool timed = input.cloud.times_s != nullptr;
  const FramePoints points = timed ? deskew_points(backend, input, scratch.input, stream) : input;
  if (timed) {
    stats.points_deskewed = input.cloud.count;
    profile.mark("0 de-skew");
  }
  const float voxel_size = map.voxel_size_m();
  const RayParameters ray_parameters = ray_parameters_of(config, voxel_size, T_map_sensor);
  TsdfFramePlan plan = plan_rays(config, points);
  FrameRays rays;
  if (plan.method == TsdfIntegrationMethod::kMerged) {
    // Merge keys from a box around the sensor (no pass over the points first); the merge table
    // hashes them, so their length costs nothing.
    const MergeKeys merge_keys =
        make_merge_keys(ray_parameters.T_world_sensor.translation, config.max_ray_length_m,
                        voxel_size, map.voxels_per_side());
    rays = merge_rays(frame, points, ray_parameters, merge_keys);
    profile.mark("1 rays: merge + tally");
  } else {
    rays = point_rays(frame, points, ray_parameters);
  }
  count_rays(rays.tally, &stats);
  if (stats.voxel_updates == 0) return stats;
  plan_visits(&plan, config, strategy, Backend::kDevice, rays, map, scratch.blocks.last_listed);
  const WeightParameters weight_parameters = weight_parameters_of(config, voxel_size);
  FrameUpdates updates;
  if (plan.sums_every_visit()) {
    updates = ray_groups_frame(plan, rays, voxel_size, weight_parameters);
    profile.mark("2a walk: ray groups");
  } else {
    updates = ray_pieces_frame(frame, plan, rays, voxel_size, weight_parameters);
    profile.mark("2a walk: piece table");
  }
  fuse_frame(frame, plan, updates, &stats);
  return stats;
}

}  // namespace tsdf

template <class Backend>
IntegrationStats tsdf_integrate_points(Backend backend, const TsdfIntegratorConfig& config,
                                       const tsdf::FrameStrategy& strategy, map::TsdfMap& map,
                                       const PointCloudView& cloud,
                                       const Eigen::Isometry3d& T_map_sensor,
                                       TsdfScratchBuffers& scratch, const Stream& stream) {
  return tsdf::integrate_frame(backend, config, strategy, map,
                               tsdf::frame_points(config, cloud, nullptr), T_map_sensor, scratch,
                               stream);
}

template <class Backend>
IntegrationStats tsdf_integrate_depth_image(Backend backend, const TsdfIntegratorConfig& config,
                                            const tsdf::FrameStrategy& strategy, map::TsdfMap& map,
                                            const tsdf::DepthImagePoints& image,
                                            const Eigen::Isometry3d& T_map_camera,
                                            TsdfScratchBuffers& scratch, const Stream& stream) {
  const int64_t pixels = image.pixels();
  // The points (and colours) are written where the view names them: by the merge, or by the
  // unprojection before the simple method's first kernel.
  scratch.input.points.resize_discard(pixels);
  if (image.colors) scratch.input.colors.resize_discard(pixels);
  PointCloudView cloud;
  cloud.points = scratch.input.points.data();
  cloud.colors = image.colors ? scratch.input.colors.data() : nullptr;
  cloud.count = pixels;
  return tsdf::integrate_frame(backend, config, strategy, map,
                               tsdf::frame_points(config, cloud, &image), T_map_camera, scratch,
                               stream);
}

template <class Backend>
void tsdf_unproject_depth(Backend backend, const tsdf::DepthImagePoints& image,
                          TsdfScratchBuffers& scratch, const Stream& stream) {
  tsdf::unproject_depth(backend, image, scratch.input, stream);
}

#define COVOX_INSTANTIATE_TSDF_INTEGRATOR(Backend)                                          \
  template IntegrationStats tsdf_integrate_points<Backend>(                                 \
      Backend, const TsdfIntegratorConfig&, const tsdf::FrameStrategy&, map::TsdfMap&,      \
      const PointCloudView&, const Eigen::Isometry3d&, TsdfScratchBuffers&, const Stream&); \
  template IntegrationStats tsdf_integrate_depth_image<Backend>(                            \
      Backend, const TsdfIntegratorConfig&, const tsdf::FrameStrategy&, map::TsdfMap&,      \
      const tsdf::DepthImagePoints&, const Eigen::Isometry3d&, TsdfScratchBuffers&,         \
      const Stream&);                                                                       \
  template void tsdf_unproject_depth<Backend>(Backend, const tsdf::DepthImagePoints&,       \
                                              TsdfScratchBuffers&, const Stream&);

}  // namespace covox::integrators

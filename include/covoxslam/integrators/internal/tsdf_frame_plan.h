#pragma once
// The plan of a TSDF frame: one small value, decided once per frame from the configuration, the
// frame strategy (tsdf_frame_strategy.h), the backend and the frame's tally, that every stage of
// the frame reads (tsdf_integrator_impl.h) instead of deciding for itself.
#include <algorithm>
#include <cstdint>
#include <string>

#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/internal/tsdf_frame_strategy.h"
#include "covoxslam/integrators/internal/tsdf_ray_tally.h"
#include "covoxslam/integrators/internal/tsdf_scratch.h"
#include "covoxslam/integrators/internal/tsdf_group_updates_cpu.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/integrators/internal/tsdf_kernels.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox::integrators::tsdf {

// What every stage of a frame works with.
template <class Backend>
struct FrameContext {
  Backend backend;
  const Stream& stream;
  const TsdfIntegratorConfig& config;
  map::TsdfMap& map;
  TsdfScratchBuffers& scratch;
  StageProfiler::Scope& profile;
};

// A frame's points and what of their colour the configuration fuses: colours, else intensities
// as grey, else none. `depth_image`: the points are that image's (`cloud` then names
// scratch.input, where they are written).
struct FramePoints {
  PointCloudView cloud;
  const DepthImagePoints* depth_image = nullptr;
  const Rgb8* colors = nullptr;
  const float* intensities = nullptr;
  float grey_per_intensity = 0.0f;
  bool has_color() const { return colors || intensities; }
};
inline FramePoints frame_points(const TsdfIntegratorConfig& config, const PointCloudView& cloud,
                                const DepthImagePoints* depth_image) {
  FramePoints points;
  points.cloud = cloud;
  points.depth_image = depth_image;
  points.colors = config.integrate_color ? cloud.colors : nullptr;
  points.intensities = config.integrate_color && !points.colors ? cloud.intensities : nullptr;
  points.grey_per_intensity = 255.0f / cloud.intensity_max_value;
  return points;
}

// What the ray stages hand on: the tally and the rays (device memory), with what each ray carries
// into its visits.
struct FrameRays {
  RayTally tally;
  int64_t count = 0;
  const RaySegment* rays = nullptr;
  const uint32_t* pieces = nullptr;  // each ray's piece count, then a 0
  const Rgb8* colors = nullptr;
  const float* intensities = nullptr;
  float grey_per_intensity = 0.0f;
  const float* weights = nullptr;  // the points each ray stands for (merged rays), or null: 1
};

// How a frame merges the visits of each voxel (tsdf_frame_strategy.h).
enum class VisitMerging {
  kSortEveryVisit,  // records of every visit, sorted and reduced
  kSumFreeSpace,    // free-space visits summed in fixed point; the band's records sorted
  kSumEveryVisit,   // every visit summed in fixed point; no record
};

struct TsdfFramePlan {
  // From the configuration and the input, before the rays.
  TsdfIntegrationMethod method = TsdfIntegrationMethod::kMerged;
  bool has_color = false;
  // From the tally.
  FrameKeyCodec codec;
  int64_t total_updates = 0;  // voxel visits
  int64_t ray_count = 0;
  bool short_keys = false;    // records with 32-bit keys
  int64_t box_blocks = 0;     // blocks of the frame's box
  uint64_t box_cells = 0;     // one per key of the box
  int cell_words = 2;         // a cell's 64-bit words when every visit is summed
  bool marks_blocks = false;  // the walk marks the box's blocks (listed before the sort)
  VisitMerging visits = VisitMerging::kSortEveryVisit;
  int64_t band_bound = 0;   // band visits the rays can make: the kept records with free-space sums
  int64_t piece_bound = 0;  // the piece table's size (frames that keep records)
  bool groups_on_cpu = false;  // the CPU twin's dense grouping (tsdf_group_updates_cpu.h) sorts
  // With every visit summed: the pass that writes the voxels reads the listed blocks' count on the
  // device instead of waiting for it (when the blocks are activated as they are listed).
  bool defers_block_count = false;

  bool sums_every_visit() const { return visits == VisitMerging::kSumEveryVisit; }
  bool sums_free_space() const { return visits == VisitMerging::kSumFreeSpace; }
  bool sums_visits() const { return visits != VisitMerging::kSortEveryVisit; }
  // Records the walk writes (every visit, free-space ones as zero-weight fill) and stage 5 reads.
  int64_t record_space() const { return sums_every_visit() ? 0 : total_updates; }
};

// Boxes of up to this many blocks are always marked (the CPU twin's dense grouping needs no more),
// larger ones when they have no more blocks than the frame has records, so that listing them
// costs no more than listing the sorted records' blocks.
constexpr int64_t kAlwaysMarkedBoxBlocks = int64_t(1) << 16;
inline bool marks_blocks(int64_t box_blocks, int64_t total_updates) {
  return box_blocks <= std::max<int64_t>(kAlwaysMarkedBoxBlocks, total_updates) &&
         box_blocks < (int64_t(1) << 31);
}

// Free-space sums (tsdf_traverse.h, PieceTraversal::free_space_sums): the frame's free-space
// visits add their weights into one fixed-point cell per key of the box, and only the band's
// visits (at most band_bound) are compacted, sorted and reduced; each voxel is still written
// once. With carving most visits are free space, and near the sensor many rays cross each voxel.
// Used when the band's bound is at most a quarter of the visits, the frame has the strategy's
// minimum of visits (the CPU twin: when the strategy says so) and the box's cells (8 bytes each)
// fit the budget: the middle way for boxes too large to sum every visit.
inline bool uses_free_space_sums(const FrameStrategy& strategy, int budget_mb, Device backend,
                                 bool marks_blocks, uint64_t box_cells, int64_t band_bound,
                                 int64_t total_updates) {
  const bool wanted = backend == Device::kCpu
                          ? strategy.cpu_twin_sums_in_fixed_point
                          : total_updates >= strategy.free_space_sums_min_visits;
  const uint64_t budget = static_cast<uint64_t>(budget_mb) << 20;
  return strategy.sum_free_space_in_fixed_point && wanted && marks_blocks &&
         box_cells <= budget / sizeof(uint64_t) && 4 * band_bound <= total_updates;
}

// Every visit summed in fixed point (tsdf::VoxelSumCells: the weight, the band's distance offset
// and, with colour, the colour sums, per key of the box): no record is written, sorted or
// reduced, and one pass over the listed blocks' cells writes every voxel. A free-space visit
// costs one 64-bit atomic and a band visit two to six, instead of a record through the sort and
// the reduction. Used when the box's cells (`cell_words` words each) fit the budget; on the CPU
// twin only when the strategy says so.
inline bool sums_every_visit(const FrameStrategy& strategy, int budget_mb, Device backend,
                             bool marks_blocks, uint64_t box_cells, int cell_words) {
  const bool wanted = backend != Device::kCpu || strategy.cpu_twin_sums_in_fixed_point;
  const uint64_t budget = static_cast<uint64_t>(budget_mb) << 20;
  return strategy.sum_free_space_in_fixed_point && strategy.sum_band_in_fixed_point && wanted &&
         marks_blocks &&
         box_cells <= budget / (sizeof(uint64_t) * static_cast<uint64_t>(cell_words));
}

// A frame that sums every visit starts its pass without waiting for the count of its listed
// blocks when the last frame listed at most this many cells: then the wait is what the frame
// saves, not the pass's time lost to its loose sizing (counted_pass_threads,
// tsdf_stage_write_voxels.h). Frames with more wait for the count.
constexpr int64_t kDeferredPassMaxCells = int64_t(1) << 21;
inline bool defers_block_count(int64_t last_listed_blocks, int64_t voxels_per_block) {
  return last_listed_blocks >= 0 && last_listed_blocks * voxels_per_block <= kDeferredPassMaxCells;
}

// The plan's first part: the method and the colour.
inline TsdfFramePlan plan_rays(const TsdfIntegratorConfig& config, const FramePoints& points) {
  TsdfFramePlan plan;
  plan.method = config.method;
  plan.has_color = points.has_color();
  return plan;
}

// The rest, from the tally of a frame with visits. Throws covox::Error for a frame whose rays or
// box do not fit the records' fields.
inline void plan_visits(TsdfFramePlan* plan, const TsdfIntegratorConfig& config,
                        const FrameStrategy& strategy, Device backend, const FrameRays& rays,
                        const map::TsdfMap& map, int64_t last_listed_blocks) {
  plan->total_updates = rays.tally.voxels;
  plan->ray_count = rays.count;
  if (plan->has_color && rays.count >= static_cast<int64_t>(ColorVisit::kBandVisitBit)) {
    throw Error("TSDF integrator: " + std::to_string(rays.count) +
                " rays in one coloured frame, at most 2^31 - 1 fit a visit record's ray index");
  }
  plan->codec =
      make_frame_key_codec(rays.tally.low_voxel(), rays.tally.high_voxel(), map.voxels_per_side());
  const FrameKeyCodec& codec = plan->codec;
  plan->short_keys = codec.key_bits <= 32;
  plan->box_blocks = static_cast<int64_t>(codec.size_x) * codec.size_y * codec.size_z;
  plan->box_cells = codec.out_of_range_key;
  plan->cell_words = plan->has_color ? kSumCellWords : 2;
  plan->marks_blocks = marks_blocks(plan->box_blocks, plan->total_updates);
  // Every ray has at most voxels / kVoxelsPerPiece + 1 pieces: a bound known without a read-back.
  plan->piece_bound = plan->total_updates / kVoxelsPerPiece + plan->ray_count;
  plan->band_bound = std::min<int64_t>(
      plan->total_updates, plan->ray_count * band_visits_per_ray_bound(config.truncation_distance_m,
                                                                       map.voxel_size_m()));
  const int budget_mb = config.fixed_point_sums_max_scratch_mb;
  if (sums_every_visit(strategy, budget_mb, backend, plan->marks_blocks, plan->box_cells,
                       plan->cell_words)) {
    plan->visits = VisitMerging::kSumEveryVisit;
  } else if (uses_free_space_sums(strategy, budget_mb, backend, plan->marks_blocks, plan->box_cells,
                                  plan->band_bound, plan->total_updates)) {
    plan->visits = VisitMerging::kSumFreeSpace;
  } else {
    plan->visits = VisitMerging::kSortEveryVisit;
  }
  plan->groups_on_cpu =
      backend == Device::kCpu && !plan->sums_every_visit() && dense_grouping_fits(codec);
  plan->defers_block_count =
      plan->sums_every_visit() && defers_block_count(last_listed_blocks, map.voxels_per_block());
}

}  // namespace covox::integrators::tsdf

#pragma once
// TsdfIntegrator: fuses point clouds (LiDAR, or depth images turned into points on the device)
// into a TsdfMap by raycasting, with the "merged" update of the coVoxSLAM paper (III-C/D):
//   1. one ray per valid point, or with the merged method one per bundle of points whose
//      surface falls into one voxel (bundled in a hash table with integer sums, ranked by their
//      first point: tsdf_ray_merging.h); a ray's voxel count is known in closed form ->
//      exclusive scan gives every ray its range in one update array;
//   2. each ray walks its voxels (Amanatides-Woo, in pieces of ~8 voxels) and writes one visit
//      record per voxel: the voxel's key with its (weighted sdf, weight) update, or, in a frame
//      with colour, with the ray's index, from which step 5 recomputes the update and its
//      weighted colour (tsdf_traverse.h: 4 bytes through the sort instead of 32); it also marks
//      the blocks its kept records fall in, in a flag array over the frame's box. A free-space
//      visit (distance clamped to +truncation, so no colour: only a weight) instead adds its
//      weight to its voxel's cell of a fixed-point grid over the box, and only the band's visits
//      (at most a bound per ray, known without a read-back) are compacted into records: with
//      carving most visits are free space and near the sensor many rays cross each voxel
//      (config.sum_free_space_in_fixed_point; tsdf_integrator_impl.h, "free-space sums").
//      On the GPU, when the box's sums fit in config.fixed_point_sums_max_scratch_mb (almost
//      always), every visit is summed so, the band's distance, weight and colour too
//      (config.sum_band_in_fixed_point; tsdf::VoxelSumCells), and no record is kept at all:
//      steps 3 and 5's reduction fall away and the pass of step 5 writes every voxel. Such a
//      frame walks its rays in groups of 32 neighbours, one warp per group and piece index
//      (tsdf_traverse.h, RayGroups), without a piece table;
//   3. records are sorted by voxel key (the CPU twin groups them by block and sums each block's
//      in a dense array instead, leaving one merged record per voxel: tsdf_group_updates_cpu.h);
//   4. the marked blocks are listed (a scan of the marks) and allocated in one
//      BlockHashTable::activate batch, before step 3 on the GPU, whose sort then hides the wait
//      for the activation's totals (for boxes with more blocks than records, listed from the
//      sorted records after step 3 instead); a frame that sums every visit activates each
//      block in the scan that lists it (BlockActivator, block_activator.h) and gets the totals at
//      its end, and a small one does not wait for its block count either (its pass reads it on
//      the device);
//   5. each voxel's records are summed (a segmented reduction in tiles, core/run_sums.h) and
//      the sum, with the voxel's free-space sum, goes straight into one weighted-average write
//      per distinct voxel; a pass over the listed blocks' cells then writes the voxels that had
//      free-space visits only.
// Why this order, not DESIGN.md's "segmented reduce, allocate, write": the sums never go
// through memory, and the allocation waits for nothing but the traverse (docs/benchmarks.md,
// "seventh pass", "eighth pass"); the reduction and the single write per voxel are the same.
// No atomics touch voxel data (only integer sums in scratch: the merge's sums of points and the
// visits' sums in fixed point, exact in any order), and every float sum is taken in an order fixed
// by the input, so results are deterministic run to run. (DESIGN.md sorts every update and merges
// each voxel's with a segmented reduce; that path is kept, for boxes too large for the sums and
// as the reference of the tests. Summing the visits as integers gives the same map up to the
// fixed point's rounding, 2^-32 of a unit weight, with no sort: 0.64-0.82 of the frame time on
// the H100, docs/benchmarks.md, "ninth pass" and "tenth pass".) The CPU twin
// runs the same kernels except in four places, each with the same result (step 3's sums within
// float rounding: the GPU adds a long run's pieces as a tree) and a comment saying why: step 3's
// grouping (with it the counts of dropped records, which the GPU finds where their runs start in
// its sorted keys), the piece table of step 2 (written one ray at a time, its cut voxels kept for
// the traverse; on the GPU one thread per piece, inside the scan of the pieces' sizes; a frame
// that sums every visit - on the GPU almost always, on the CPU twin only in the tests - has no
// piece table on either backend and walks its rays in groups), the
// merge's tally (a reduction instead of per-warp atomics), and step 4's activation (queued on the
// GPU for the blocks counted on the device, its totals read back while the records sort; on the
// CPU after reading the count, which costs nothing there).
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/tsdf_integrator_config.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {

// What one integration did; counters of dropped input are the "counted, logged drop".
struct IntegrationStats {
  int64_t points_in = 0;
  int64_t surface_rays = 0;
  int64_t clearing_rays = 0;
  int64_t dropped_non_finite = 0;
  int64_t dropped_zero = 0;
  int64_t dropped_too_close = 0;
  int64_t dropped_too_far = 0;
  int64_t rays_cast = 0;            // surface + clearing rays after merging points per voxel
  int64_t voxel_updates = 0;        // before merging
  int64_t voxels_updated = 0;       // distinct voxels written
  int64_t voxels_out_of_range = 0;  // voxels dropped: block outside the map's key range
  int64_t blocks_allocated = 0;     // new blocks this call
  int64_t records_grouped = 0;      // visit records grouped by voxel (sorted) and reduced: every
                                    // visit, or with free-space sums the band's (a bound on them)

  int64_t dropped_total() const {
    return dropped_non_finite + dropped_zero + dropped_too_close + dropped_too_far;
  }
};

// Points (and optional colours) in the sensor frame, in memory of the map's device.
// Without colours, an intensity channel (LiDAR) is fused as grey: intensity / intensity_max_value.
struct PointCloudView {
  const Vec3f* points = nullptr;
  const Rgb8* colors = nullptr;  // optional
  int64_t count = 0;
  const float* intensities = nullptr;  // optional, used when colors is null
  float intensity_max_value = 255.0f;  // intensity shown as white
};

// A pinhole camera; depth pixel (u, v) with depth z unprojects to ((u-cx) z/fx, (v-cy) z/fy, z).
struct PinholeIntrinsics {
  float fx = 0.0f, fy = 0.0f, cx = 0.0f, cy = 0.0f;
  int width = 0, height = 0;
};

// A depth image in memory of the map's device: either 16-bit raw values as sensors and datasets
// store them (`depth`, with depth_units_per_m and invalid_value), or metres (`depth_m`, 0 or
// non-finite = no measurement).
struct DepthImageView {
  const uint16_t* depth = nullptr;  // row-major, width x height
  const float* depth_m = nullptr;   // used instead of `depth` when set
  const Rgb8* colors = nullptr;     // optional, registered to the depth image
  PinholeIntrinsics intrinsics;
  float depth_units_per_m = 1000.0f;  // 1000 for millimetres (Kinect, 7-Scenes), 6553.5 Replica
  uint16_t invalid_value = 0;         // 0 is always invalid; this one too (e.g. 65535)
};

class TsdfIntegrator {
 public:
  explicit TsdfIntegrator(const TsdfIntegratorConfig& config);
  ~TsdfIntegrator();
  TsdfIntegrator(TsdfIntegrator&&) noexcept;
  TsdfIntegrator& operator=(TsdfIntegrator&&) noexcept;

  const TsdfIntegratorConfig& config() const { return config_; }

  // Integrates a cloud taken at pose T_map_sensor. Device memory of map.device().
  IntegrationStats integrate(TsdfMap& map, const PointCloudView& cloud,
                             const Eigen::Isometry3d& T_map_sensor, const Stream& stream);
  // Host-memory convenience: uploads, then integrates.
  IntegrationStats integrate(TsdfMap& map, const std::vector<Vec3f>& points,
                             const std::vector<Rgb8>& colors,
                             const Eigen::Isometry3d& T_map_sensor);
  // Unprojects a depth image on the device (its points and colours in tiles of 8 x 4 pixels:
  // tsdf::pixel_tile_order), then integrates the points.
  IntegrationStats integrate_depth(TsdfMap& map, const DepthImageView& image,
                                   const Eigen::Isometry3d& T_map_camera, const Stream& stream);

 private:
  struct Scratch;
  TsdfIntegratorConfig config_;
  std::unique_ptr<Scratch> scratch_;
};

}  // namespace covox

#pragma once
// Parameters of TSDF integration. Names and meanings follow voxblox, so a voxblox user's
// configuration carries over; defaults follow voxblox except where noted.
#include <cstdint>
#include <string>

namespace covox {

// How points become rays (voxblox's `method`).
enum class TsdfIntegrationMethod {
  kSimple,  // one ray per point
  kMerged,  // points whose surface falls into one voxel share one ray from their mean, with
            // their summed weight and mean colour (voxblox's default): far fewer rays for dense
            // depth images and for LiDAR returns near the sensor
};

struct TsdfIntegratorConfig {
  TsdfIntegrationMethod method = TsdfIntegrationMethod::kMerged;
  // Half-width of the band around the surface where signed distances are stored. Voxels further
  // in front are "free" (distance clamped to +truncation); further behind are not updated.
  float truncation_distance_m = 0.6f;  // voxgraph's ARCHE setting: 3 voxels of 0.2 m
  // Cap on a voxel's accumulated weight: lower values let the map forget faster.
  float max_weight = 10000.0f;
  // Points closer than this to the sensor are dropped (robot body, lens dirt).
  float min_ray_length_m = 0.1f;
  // Points further than this are dropped, or only clear free space when allow_clear is set.
  float max_ray_length_m = 5.0f;
  // Update every voxel from the sensor to the surface (free space), not only the band.
  bool voxel_carving_enabled = true;
  // Points beyond max_ray_length_m still carve free space up to max_ray_length_m.
  bool allow_clear = true;
  // Weighting (voxblox): constant 1 instead of the inverse-square of the measured range.
  bool use_const_weight = false;
  // Linear drop-off of the weight behind the surface, from -voxel_size to -truncation.
  bool use_weight_dropoff = true;
  // Multiply the weight of voxels inside the truncation band by sparsity_compensation_factor,
  // so that sparse LiDAR surface hits are not washed out by the many free-space updates.
  bool use_sparsity_compensation_factor = false;
  float sparsity_compensation_factor = 1.0f;
  // Fuse colour (when the input has it) inside the truncation band.
  bool integrate_color = true;
  // How free-space visits (distance clamped to +truncation, no colour) are merged per voxel:
  // true sums their weights in fixed point as the rays are walked (exact, so order-free and
  // deterministic) and sorts only the band's visits, which is much faster with carving; false
  // sorts every visit (the reference the tests compare with). The map is the same up to the
  // fixed point's rounding (2^-32 of a unit weight). The sums take 8 bytes of scratch per voxel
  // of the frame's box (frames whose box does not fit in fixed_point_sums_max_scratch_mb sort
  // every visit). Not a ROS parameter.
  bool sum_free_space_in_fixed_point = true;
  // ... on the GPU for frames of at least this many voxel visits (and at least 4 per band visit
  // the rays can make): below it the sums' extra passes cost more than the smaller sort saves
  // (H100: the 7-Scenes 5 cm frame, 0.3 M visits, 8 % slower with them; the 2 cm one, 3.8 M,
  // faster). The CPU twin, whose dense grouping merges visits per block anyway, uses them only
  // when this is 0 (the tests, which compare both ways on both backends).
  int64_t free_space_sums_min_visits = int64_t(1) << 20;
  // With sum_free_space_in_fixed_point, sum the band's visits too (weight, distance and colour,
  // in fixed point), so that no visit is sorted at all: 0.64-0.82 of the frame time on the H100
  // (docs/benchmarks.md, "tenth pass"). On the GPU for frames whose box's sums fit in
  // fixed_point_sums_max_scratch_mb (16 bytes per voxel of the box, 48 with colour); the CPU twin,
  // like free_space_sums_min_visits, only when that threshold is 0. The same map up to the fixed
  // point's rounding. Not a ROS parameter.
  bool sum_band_in_fixed_point = true;
  // Device memory the sums may take (kept between frames): frames whose box's sums of every
  // visit do not fit sum only their free-space visits (8 bytes per voxel) if those fit, else sort
  // every visit. 512 MB holds every visit of a KITTI HDL-64 scan at 0.2 m with 50 m rays (28 M
  // voxels in its box, 450 MB) and of a 7-Scenes frame at 2 cm with colour (4.6 M voxels, 220
  // MB); lower it on a Jetson with little memory to spare. 0: always sort.
  int fixed_point_sums_max_scratch_mb = 512;
  // When every visit is summed on the GPU: the free-space visits that a warp's lanes (32
  // neighbouring rays, walked side by side) make to one voxel at one step add their weights in
  // one atomic. The same map (integer sums). It pays where many rays cross the same voxels near
  // the sensor and costs the matching where few do (H100, three same-run A/Bs, 2026-11-26, frame
  // time with it / without: OS1-64 at 0.1 m 0.86-0.91, at 0.2 m 0.97-1.08, KITTI 1.06-1.22,
  // 7-Scenes 5 cm 1.06-1.07, 2 cm 1.03-1.15; docs/benchmarks.md, "eleventh pass"); off by
  // default. Ignored by the CPU twin, whose "warp" is one ray.
  bool aggregate_free_space_in_warp = false;
};

// "simple" or "merged"; throws covox::Error naming the bad value otherwise.
TsdfIntegrationMethod parse_tsdf_integration_method(const std::string& name);
const char* to_string(TsdfIntegrationMethod method);

// Throws covox::Error naming the first invalid parameter.
void validate(const TsdfIntegratorConfig& config, float voxel_size_m);

}  // namespace covox

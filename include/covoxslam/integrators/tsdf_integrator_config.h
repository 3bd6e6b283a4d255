#pragma once
// Parameters of TSDF integration. Names and meanings follow voxblox, so a voxblox user's
// configuration carries over; defaults follow voxblox except where noted.
#include <cstdint>
#include <string>

namespace covox::integrators {

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
  // Device memory that the fixed-point sums of a frame's visits may take (kept between frames).
  // Visits are merged per voxel either by sorting them or by summing them in fixed point into one
  // cell per voxel of the frame's box (16 bytes per voxel, 48 with colour; 8 for free-space
  // visits only): the same map up to the fixed point's rounding (2^-32 of a unit weight), with no
  // sort and no records. Frames whose box's sums of every visit do not fit sum only their
  // free-space visits if those fit, else sort every visit. 512 MB holds every visit of a 64-beam
  // LiDAR scan at 0.2 m with 50 m rays (28 M voxels in its box, 450 MB) and of an RGB-D frame at
  // 2 cm with colour (4.6 M voxels, 220 MB); lower it where memory is short. 0: always sort.
  int fixed_point_sums_max_scratch_mb = 512;
};

// "simple" or "merged"; throws covox::Error naming the bad value otherwise.
TsdfIntegrationMethod parse_tsdf_integration_method(const std::string& name);
const char* to_string(TsdfIntegrationMethod method);

// Throws covox::Error naming the first invalid parameter.
void validate(const TsdfIntegratorConfig& config, float voxel_size_m);

}  // namespace covox::integrators

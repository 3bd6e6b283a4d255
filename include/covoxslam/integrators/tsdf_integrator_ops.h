#pragma once
// Backend-templated steps of TsdfIntegrator (defined in tsdf_integrator_impl.h, instantiated per
// backend). Scratch buffers are passed in so steady-state frames allocate nothing.
#include <array>
#include <cstdint>

#include <Eigen/Geometry>

#include "covoxslam/core/buffer.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/integrators/tsdf_kernels.h"
#include "covoxslam/integrators/tsdf_ray_merging.h"

namespace covox {

struct TsdfScratchBuffers {
  explicit TsdfScratchBuffers(Device device)
      : points(device), colors(device), rays(device), counts(device), offsets(device),
        keys(device), order(device), updates(device), merged_keys(device), merged(device),
        block_indices(device), slots(device), is_new(device), merged_bundles(device),
        ray_colors(device), ray_weights(device), block_flags(device), block_ranks(device), keys_alt(device),
        order_alt(device), keys32(device), keys32_alt(device), merged_keys32(device), distance_updates(device), distance_updates_alt(device), pieces(device), piece_voxels(device), piece_offsets(device), readback(device) {}
  Buffer<Vec3f> points;  // depth images unprojected, or host clouds uploaded
  Buffer<Rgb8> colors;
  Buffer<tsdf::RaySegment> rays;
  Buffer<uint32_t> counts;
  Buffer<uint32_t> offsets;
  Buffer<uint64_t> keys;
  Buffer<uint32_t> order;
  Buffer<tsdf::VoxelUpdate> updates;
  Buffer<uint64_t> merged_keys;
  Buffer<tsdf::VoxelUpdate> merged;
  Buffer<Index3D> block_indices;
  Buffer<uint32_t> slots;
  Buffer<uint8_t> is_new;
  // merged integration only
  Buffer<tsdf::PointBundle> merged_bundles;
  Buffer<Rgb8> ray_colors;
  Buffer<float> ray_weights;
  // distinct blocks of the merged voxels
  Buffer<uint32_t> block_flags;
  Buffer<uint32_t> block_ranks;
  // radix sort scratch
  Buffer<uint64_t> keys_alt;
  Buffer<uint32_t> order_alt;
  // update keys of frames whose keys fit in 32 bits
  Buffer<uint32_t> keys32;
  Buffer<uint32_t> keys32_alt;
  Buffer<uint32_t> merged_keys32;
  // The update keys, their radix-sort scratch and the merged keys, for 64- or 32-bit keys.
  template <class KeyT>
  std::array<Buffer<KeyT>*, 3> update_key_buffers() {
    if constexpr (sizeof(KeyT) == sizeof(uint32_t)) {
      return {&keys32, &keys32_alt, &merged_keys32};
    } else {
      return {&keys, &keys_alt, &merged_keys};
    }
  }
  // frames without colour: 8-byte updates sorted with their keys (no permutation to gather by)
  Buffer<tsdf::DistanceUpdate> distance_updates;
  Buffer<tsdf::DistanceUpdate> distance_updates_alt;
  // ray pieces (tsdf_kernels.h): the piece table, voxels per piece and their update offsets
  Buffer<tsdf::RayPiece> pieces;
  Buffer<uint32_t> piece_voxels;
  Buffer<uint32_t> piece_offsets;
  // counts computed on the device and read back together in one copy
  Buffer<uint32_t> readback;
};

template <class Backend>
IntegrationStats tsdf_integrate_points(Backend backend, const TsdfIntegratorConfig& config,
                                       TsdfMap& map, const PointCloudView& cloud,
                                       const Eigen::Isometry3d& T_map_sensor,
                                       TsdfScratchBuffers& scratch, const Stream& stream);

// Writes width*height points (invalid pixels become (0,0,0), which integration drops as zero
// points) and colours into scratch.points / scratch.colors.
template <class Backend>
void tsdf_unproject_depth(Backend backend, const DepthImageView& image, TsdfScratchBuffers& scratch,
                          const Stream& stream);

}  // namespace covox

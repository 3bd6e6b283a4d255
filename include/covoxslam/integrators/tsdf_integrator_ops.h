#pragma once
// Backend-templated steps of TsdfIntegrator (defined in tsdf_integrator_impl.h, instantiated per
// backend). Scratch buffers are passed in so steady-state frames allocate nothing.
#include <array>
#include <cstdint>
#include <memory>
#include <type_traits>

#include <Eigen/Geometry>

#include "covoxslam/core/buffer.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/integrators/tsdf_kernels.h"
#include "covoxslam/integrators/tsdf_ray_merging.h"

namespace covox {

struct TsdfScratchBuffers {
  explicit TsdfScratchBuffers(Device device)
      : points(device),
        colors(device),
        rays(device),
        counts(device),
        offsets(device),
        keys(device),
        merged_keys(device),
        block_indices(device),
        slots(device),
        is_new(device),
        point_codes(device),
        ray_scan_scratch(device),
        ray_points(device),
        merge_table_keys(device),
        merge_table_bundles(device),
        merge_tally(device),
        merge_warps_done(device),
        ray_colors(device),
        ray_weights(device),
        block_flags(device),
        block_ranks(device),
        keys_alt(device),
        keys32(device),
        keys32_alt(device),
        merged_keys32(device),
        distance_records(device),
        distance_records_alt(device),
        color_visits(device),
        color_visits_alt(device),
        merged_updates(device),
        pieces(device),
        piece_first_voxels(device),
        piece_voxels(device),
        piece_offsets(device),
        run_tile_parts(device),
        readback(device),
        box_marks(device),
        fixed_point_sums(device),
        record_ranks(device) {}
  Buffer<Vec3f> points;  // depth images unprojected, or host clouds uploaded
  Buffer<Rgb8> colors;
  Buffer<tsdf::RaySegment> rays;
  Buffer<uint32_t> counts;
  Buffer<uint32_t> offsets;
  Buffer<uint64_t> keys;
  Buffer<uint64_t> merged_keys;
  Buffer<Index3D> block_indices;
  Buffer<uint32_t> slots;
  Buffer<uint8_t> is_new;
  // merged integration only (tsdf_ray_merging.h): what each point became, the points that emit
  // rays, the bundle table (kept between frames, clean after each), the rays' weights and
  // colours
  Buffer<uint32_t> point_codes;
  Buffer<uint32_t> ray_scan_scratch;  // the CPU twin's scratch for the scan that lists ray_points
  Buffer<uint32_t> ray_points;        // each ray's emitting point, then the count of rays
  Buffer<uint64_t> merge_table_keys;
  Buffer<tsdf::PointBundle> merge_table_bundles;
  bool merge_table_clean = false;
  bool merge_tally_clean = false;  // reset by the last frame at its end
  Buffer<tsdf::MergeTally> merge_tally;
  // The GPU's hand-off of the tally (tsdf::MergeTallySummary): the ray kernel's warps done (one
  // word, zero between frames: the last warp resets it), the summary it writes to mapped host
  // memory, and the frame's sequence number that stamps it.
  Buffer<uint32_t> merge_warps_done;
  std::unique_ptr<MappedHostBytes> merge_summary;
  uint32_t merge_sequence = 0;
  Buffer<Rgb8> ray_colors;
  Buffer<float> ray_weights;
  // distinct blocks of the merged voxels
  Buffer<uint32_t> block_flags;
  Buffer<uint32_t> block_ranks;
  // radix sort scratch
  Buffer<uint64_t> keys_alt;
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
  // The visit records' values and their radix-sort scratch (tsdf_traverse.h): distance updates
  // without colour, ray indices with it.
  Buffer<tsdf::DistanceUpdate> distance_records;
  Buffer<tsdf::DistanceUpdate> distance_records_alt;
  Buffer<tsdf::ColorVisit> color_visits;
  Buffer<tsdf::ColorVisit> color_visits_alt;
  template <class ValueT>
  std::array<Buffer<ValueT>*, 2> record_value_buffers() {
    if constexpr (std::is_same<ValueT, tsdf::ColorVisit>::value) {
      return {&color_visits, &color_visits_alt};
    } else {
      return {&distance_records, &distance_records_alt};
    }
  }
  // Per-voxel sums of a coloured frame (a frame without colour sums into distance_records_alt).
  Buffer<tsdf::VoxelUpdate> merged_updates;
  // ray pieces (tsdf_kernels.h): the piece table, voxels per piece and their update offsets
  Buffer<tsdf::RayPiece> pieces;
  Buffer<Index3D> piece_first_voxels;  // the CPU twin's: each piece's first voxel
  Buffer<uint32_t> piece_voxels;
  Buffer<uint32_t> piece_offsets;
  Buffer<uint64_t> run_tile_parts;  // consume_run_sums' partial sums at tile edges
  // counts computed on the device and read back together in one copy
  Buffer<uint32_t> readback;
  // the traverse's marks of the blocks of the frame's box (clear between frames)
  Buffer<uint32_t> box_marks;
  bool box_marks_clean = false;
  // the visits' fixed-point sums over the frame's box: every visit's (tsdf::VoxelSumCells) or the
  // free-space visits' weights, one word per key (clear between frames: each frame clears the
  // cells it used; one buffer for both, so the scratch stays within the budget), and the kept
  // records' ranks for the CPU twin's compaction of the band's records (tsdf_integrator_impl.h)
  Buffer<uint64_t> fixed_point_sums;
  bool fixed_point_sums_clean = false;
  Buffer<uint32_t> record_ranks;
  // The blocks the last frame listed (-1: none yet): how many threads to start for a pass whose
  // count only the device knows (tsdf_integrator_impl.h, step 5).
  int64_t last_listed_blocks = -1;
};

template <class Backend>
IntegrationStats tsdf_integrate_points(Backend backend, const TsdfIntegratorConfig& config,
                                       TsdfMap& map, const PointCloudView& cloud,
                                       const Eigen::Isometry3d& T_map_sensor,
                                       TsdfScratchBuffers& scratch, const Stream& stream);

// Integrates a depth image's points (tsdf::DepthImagePoints, in tile order). The merged method
// reads the image in place: its first kernel unprojects each pixel as it bundles it and writes
// the points for the kernels after it (one kernel and one pass over the points fewer per frame
// than unprojecting first); the simple method has the image unprojected first.
template <class Backend>
IntegrationStats tsdf_integrate_depth_image(Backend backend, const TsdfIntegratorConfig& config,
                                            TsdfMap& map, const tsdf::DepthImagePoints& image,
                                            const Eigen::Isometry3d& T_map_camera,
                                            TsdfScratchBuffers& scratch, const Stream& stream);

// Writes width*height points (invalid pixels become (0,0,0), which integration drops as zero
// points) and colours into scratch.points / scratch.colors, in tile order (tsdf::pixel_tile_order,
// tsdf_kernels.h).
template <class Backend>
void tsdf_unproject_depth(Backend backend, const tsdf::DepthImagePoints& image,
                          TsdfScratchBuffers& scratch, const Stream& stream);

}  // namespace covox

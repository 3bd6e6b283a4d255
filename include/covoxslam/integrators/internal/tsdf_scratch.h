#pragma once
// The scratch memory of TSDF frames, kept between frames so that steady-state frames allocate
// nothing: one struct per stage that owns the buffers (internal/tsdf_stage_*.h).
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <type_traits>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/internal/tsdf_frame_results.h"
#include "covoxslam/integrators/internal/tsdf_kernels.h"
#include "covoxslam/integrators/internal/tsdf_ray_merging.h"

namespace covox::integrators {

struct TsdfScratchBuffers {
  // The frame's points when they are not the caller's: depth images unprojected (or read in place
  // by the merge, which writes them here), host clouds uploaded.
  struct Input {
    explicit Input(Device device) : points(device), colors(device), deskewed_points(device) {}
    Buffer<Vec3f> points;
    Buffer<Rgb8> colors;
    Buffer<Vec3f> deskewed_points;  // stage 0: a timed cloud's points at the cloud's pose
  };
  // The merge of points into rays (tsdf_ray_merging.h, internal/tsdf_stage_merge_rays.h).
  struct Merge {
    explicit Merge(Device device)
        : point_codes(device),
          ray_scan_scratch(device),
          ray_points(device),
          table_keys(device),
          table_bundles(device),
          tally(device),
          warps_done(device) {}
    Buffer<uint32_t> point_codes;       // what each point became (its bundle's slot, or a code)
    Buffer<uint32_t> ray_scan_scratch;  // the CPU twin's scratch for the scan that lists ray_points
    Buffer<uint32_t> ray_points;        // each ray's emitting point, then the count of rays
    // The bundle table, clean between frames: each frame frees the slots it used.
    Buffer<uint64_t> table_keys;
    Buffer<tsdf::PointBundle> table_bundles;
    bool table_clean = false;
    // The tally's stripes, reset by each frame at its end.
    Buffer<tsdf::MergeTally> tally;
    bool tally_clean = false;
    // The GPU's hand-off of the tally (tsdf::MergeTallySummary): the ray kernel's warps done (one
    // word, zero between frames: the last warp resets it), the summary it writes to mapped host
    // memory, and the frame's sequence number that stamps it.
    Buffer<uint32_t> warps_done;
    std::unique_ptr<MappedHostBytes> summary;
    uint32_t sequence = 0;
  };
  // The frame's rays, with what each carries into its visits.
  struct Rays {
    explicit Rays(Device device) : rays(device), colors(device), weights(device), pieces(device) {}
    Buffer<tsdf::RaySegment> rays;
    Buffer<Rgb8> colors;    // merged rays' mean colours
    Buffer<float> weights;  // merged rays: the points each stands for
    // Each ray's piece count, then a 0 for the scan's end. (Dead once the visits are walked: the
    // frame's end reuses it for the rare count of rejected voxels.)
    Buffer<uint32_t> pieces;
  };
  // The piece table (tsdf_kernels.h) of frames that keep records.
  struct Pieces {
    explicit Pieces(Device device)
        : first_pieces(device),
          table(device),
          first_voxels(device),
          voxels(device),
          first_records(device) {}
    Buffer<uint32_t> first_pieces;  // each ray's first piece, then the pieces' total
    Buffer<tsdf::RayPiece> table;
    Buffer<Index3D> first_voxels;  // the CPU twin's: each piece's first voxel
    Buffer<uint32_t> voxels;       // the CPU twin's: each piece's voxel count
    Buffer<uint32_t> first_records;
  };
  // What the walk of the visits leaves over the frame's box: the blocks' marks, and the visits'
  // fixed-point sums (every visit's, tsdf::VoxelSumCells, or the free-space visits' weights; one
  // buffer for both, so the scratch stays within the budget). Each is clear between frames (each
  // frame clears what it used); `clean` is false from the frame's first write until it has.
  struct BoxGrids {
    explicit BoxGrids(Device device) : block_marks(device), sums(device) {}
    Buffer<uint32_t> block_marks;
    bool block_marks_clean = false;
    Buffer<uint64_t> sums;
    bool sums_clean = false;
  };
  // The visit records, their radix sort's scratch and the merged voxels, for 32- or 64-bit keys.
  struct Records {
    explicit Records(Device device)
        : keys(device),
          keys_alt(device),
          merged_keys(device),
          keys32(device),
          keys32_alt(device),
          merged_keys32(device),
          distance_records(device),
          distance_records_alt(device),
          color_visits(device),
          color_visits_alt(device),
          merged_updates(device),
          band_ranks(device),
          run_tile_parts(device) {}
    Buffer<uint64_t> keys;
    Buffer<uint64_t> keys_alt;
    Buffer<uint64_t> merged_keys;
    Buffer<uint32_t> keys32;
    Buffer<uint32_t> keys32_alt;
    Buffer<uint32_t> merged_keys32;
    // The records' values (tsdf_traverse.h): distance updates without colour, ray indices with it.
    Buffer<tsdf::DistanceUpdate> distance_records;
    Buffer<tsdf::DistanceUpdate> distance_records_alt;
    Buffer<tsdf::ColorVisit> color_visits;
    Buffer<tsdf::ColorVisit> color_visits_alt;
    // Per-voxel sums of a coloured frame grouped by the CPU twin (a frame without colour sums
    // into distance_records).
    Buffer<tsdf::VoxelUpdate> merged_updates;
    Buffer<uint32_t> band_ranks;      // the CPU twin's compaction of the band's records
    Buffer<uint64_t> run_tile_parts;  // consume_run_sums' partial sums at tile edges
    // The keys, their sort's scratch and the merged keys.
    template <class KeyT>
    std::array<Buffer<KeyT>*, 3> key_buffers() {
      if constexpr (sizeof(KeyT) == sizeof(uint32_t)) {
        return {&keys32, &keys32_alt, &merged_keys32};
      } else {
        return {&keys, &keys_alt, &merged_keys};
      }
    }
    // The values and their sort's scratch.
    template <class ValueT>
    std::array<Buffer<ValueT>*, 2> value_buffers() {
      if constexpr (std::is_same<ValueT, tsdf::ColorVisit>::value) {
        return {&color_visits, &color_visits_alt};
      } else {
        return {&distance_records, &distance_records_alt};
      }
    }
  };
  // The frame's distinct blocks, their slots in the map, and how they were listed.
  struct Blocks {
    explicit Blocks(Device device)
        : indices(device), slots(device), is_new(device), flags(device), ranks(device) {}
    Buffer<Index3D> indices;
    Buffer<uint32_t> slots;
    Buffer<uint8_t> is_new;
    Buffer<uint32_t> flags;  // listed from sorted records: whether a record starts its block
    Buffer<uint32_t> ranks;  // the scan of the box's marks, or of the sorted records' flags
    // The blocks the last frame listed (-1: none yet): how many threads to start for a pass whose
    // count only the device knows (internal/tsdf_stage_write_voxels.h).
    int64_t last_listed = -1;
  };

  explicit TsdfScratchBuffers(Device device)
      : input(device),
        merge(device),
        rays(device),
        pieces(device),
        grids(device),
        records(device),
        blocks(device),
        results(device) {}
  Device device() const { return results.device(); }

  Input input;
  Merge merge;
  Rays rays;
  Pieces pieces;
  BoxGrids grids;
  Records records;
  Blocks blocks;
  Buffer<tsdf::FrameResults> results;  // one element
};

namespace tsdf {

// A scratch array that the frame that uses it leaves all zero: cleared here only when it grows or
// when the last frame did not get that far; `clean` stays false until the frame clears it.
template <class T>
T* clean_frame_scratch(Buffer<T>& buffer, bool& clean, size_t needed, const Stream& stream) {
  if (buffer.size() < needed || !clean) {
    const size_t size = std::max(needed, buffer.size());
    buffer.resize_discard(size);
    set_bytes(buffer.data(), buffer.device(), 0, size * sizeof(T), stream);
  }
  clean = false;
  return buffer.data();
}

}  // namespace tsdf
}  // namespace covox::integrators

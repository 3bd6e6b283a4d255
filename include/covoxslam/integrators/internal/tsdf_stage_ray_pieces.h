#pragma once
// Stage 2a of a TSDF frame: how its visits will be walked. A frame that keeps records walks its
// rays in pieces of ~kVoxelsPerPiece voxels (tsdf_kernels.h), one thread each, from a piece table
// (each piece's ray and index) and each piece's first record (a scan of the pieces' voxel
// counts); a frame that sums every visit walks them in groups of neighbouring rays, without a
// table (tsdf_traverse.h, RayGroups).
#include <cstdint>

#include "covoxslam/core/parallel.h"
#include "covoxslam/core/sorted_search.h"
#include "covoxslam/integrators/internal/tsdf_frame_plan.h"

namespace covox::integrators::tsdf {

// The frame's visits as the walk sees them, without a piece table.
inline FrameUpdates frame_updates(const TsdfFramePlan& plan, const FrameRays& rays,
                                  float voxel_size, const WeightParameters& weight_parameters) {
  return FrameUpdates{
      plan.codec,   plan.total_updates, 0,           nullptr,          nullptr,
      nullptr,      rays.rays,          rays.colors, rays.intensities, rays.grey_per_intensity,
      rays.weights, 1.0f / voxel_size,  voxel_size,  weight_parameters};
}

// Every visit summed: the rays are walked in groups, each group in as many levels as the longest
// ray has pieces (from the tally).
inline FrameUpdates ray_groups_frame(const TsdfFramePlan& plan, const FrameRays& rays,
                                     float voxel_size, const WeightParameters& weight_parameters) {
  FrameUpdates frame = frame_updates(plan, rays, voxel_size, weight_parameters);
  frame.walks_ray_groups = true;
  frame.ray_pieces = rays.pieces;
  frame.most_ray_pieces = static_cast<uint32_t>(rays.tally.most_pieces);
  frame.ray_count = rays.count;
  return frame;
}

// The CPU twin's piece table: one ray per call, its cuts in order, each cut voxel computed once
// (it ends one piece and starts the next) and kept for the traverse, which then computes none.
// Call i also zeroes the i-th count past the last piece: there are at most ray_count of them
// (piece_bound - ray_count is at most the pieces' total voxels / kVoxelsPerPiece).
struct ListRayPieces {
  const RaySegment* rays;
  const uint32_t* ray_pieces;
  const uint32_t* first_piece;
  const uint32_t* piece_total;
  int64_t piece_bound;
  float inverse_voxel_size;
  RayPiece* pieces;
  Index3D* firsts;
  uint32_t* piece_voxels;
  void operator()(int64_t i) const {
    if (*piece_total + i < piece_bound) piece_voxels[*piece_total + i] = 0;
    const uint32_t count = ray_pieces[i];
    for_each_ray_piece(rays[i], count, inverse_voxel_size,
                       [&](uint32_t k, const Index3D& first, uint32_t voxels) {
                         const uint32_t p = first_piece[i] + k;
                         pieces[p] = RayPiece{static_cast<uint32_t>(i), k, count};
                         firsts[p] = first;
                         piece_voxels[p] = voxels;
                       });
  }
};

// The GPU's piece table, written by the scan of the pieces' voxel counts, which computes them
// (one launch instead of a kernel and a scan): piece p finds its ray by a binary search of the
// rays' first pieces (a few kilobytes, cached), writes its table entry and counts its own voxels;
// the traverse computes the cuts again. (Not the CPU twin's loop over a ray's cuts: it serialises
// long rays, and a table carrying the cut voxels doubles its strided writes.) The counts past the
// last piece are zero for the scan over the bound.
struct CountPieceVoxels {
  const RaySegment* rays;
  const uint32_t* ray_pieces;
  const uint32_t* first_piece;
  const uint32_t* piece_total;
  int64_t ray_count;
  float inverse_voxel_size;
  RayPiece* pieces;
  COVOX_HD_INLINE uint32_t operator()(int64_t p) const {
    if (p >= *piece_total) return 0u;
    const uint32_t piece = static_cast<uint32_t>(p);
    // the last ray whose first piece is at or before p (rays without pieces share the next one's)
    const uint32_t i =
        static_cast<uint32_t>(lower_bound_index(first_piece, ray_count, piece + 1u) - 1);
    const uint32_t index = piece - first_piece[i];
    const uint32_t count = ray_pieces[i];
    pieces[p] = RayPiece{i, index, count};
    return ray_piece_voxel_count(rays[i], index, count, inverse_voxel_size);
  }
};

// The piece table and each piece's first record.
template <class Backend>
void write_piece_table(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                       const FrameRays& rays, float inverse_voxel_size,
                       const Index3D** piece_first_voxels) {
  TsdfScratchBuffers::Pieces& scratch = frame.scratch.pieces;
  const int64_t ray_count = rays.count;
  const int64_t piece_bound = plan.piece_bound;
  const uint32_t* first_piece = scratch.first_pieces.data();
  const uint32_t* piece_total = first_piece + ray_count;  // on the device
  scratch.table.resize_discard(piece_bound);
  scratch.first_records.resize_discard(piece_bound);
  *piece_first_voxels = nullptr;
  if constexpr (Backend::kDevice == Device::kCpu) {
    scratch.voxels.resize_discard(piece_bound);
    scratch.first_voxels.resize_discard(piece_bound);
    *piece_first_voxels = scratch.first_voxels.data();
    parallel_for(frame.backend, frame.stream, ray_count,
                 ListRayPieces{rays.rays, rays.pieces, first_piece, piece_total, piece_bound,
                               inverse_voxel_size, scratch.table.data(),
                               scratch.first_voxels.data(), scratch.voxels.data()});
    exclusive_scan(frame.backend, frame.stream, scratch.voxels.data(), piece_bound,
                   scratch.first_records.data());
  } else {
    // (one piece per thread: the binary searches are chains of dependent loads)
    exclusive_scan_of<1>(frame.backend, frame.stream, piece_bound,
                         CountPieceVoxels{rays.rays, rays.pieces, first_piece, piece_total,
                                          ray_count, inverse_voxel_size, scratch.table.data()},
                         scratch.first_records.data());
  }
}

// Stage 2a for a frame that keeps records: each ray's first piece (a scan of the rays' piece
// counts), the piece table, each piece's first record.
template <class Backend>
FrameUpdates ray_pieces_frame(const FrameContext<Backend>& frame, const TsdfFramePlan& plan,
                              const FrameRays& rays, float voxel_size,
                              const WeightParameters& weight_parameters) {
  TsdfScratchBuffers::Pieces& scratch = frame.scratch.pieces;
  scratch.first_pieces.resize_discard(rays.count + 1);
  exclusive_scan(frame.backend, frame.stream, rays.pieces, rays.count + 1,
                 scratch.first_pieces.data());
  const Index3D* piece_first_voxels = nullptr;
  write_piece_table(frame, plan, rays, 1.0f / voxel_size, &piece_first_voxels);
  FrameUpdates updates = frame_updates(plan, rays, voxel_size, weight_parameters);
  updates.piece_bound = plan.piece_bound;
  updates.piece_total = scratch.first_pieces.data() + rays.count;
  updates.pieces = scratch.table.data();
  updates.piece_first_voxels = piece_first_voxels;
  return updates;
}

}  // namespace covox::integrators::tsdf

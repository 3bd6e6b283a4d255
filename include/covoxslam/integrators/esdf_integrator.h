#pragma once
// EsdfIntegrator: exact Euclidean signed distances on the voxel grid, from the TSDF's surface
// sites, up to esdf_max_distance_m, by the exact separable distance transform
// (Felzenszwalb-Huttenlocher lower envelopes along x, y, z) over a dense window around the
// blocks whose TSDF changed (map.block_changed()): the write region is those blocks grown by
// esdf_max_distance_m, the window that region grown once more. Sites are recomputed from the
// TSDF, so a vanished site raises its neighbours' distances, and distances cross unobserved
// blocks, which wavefront propagation (voxblox, nvblox) neither guarantees nor does: its copied
// "parent" sites can miss a voxel's nearest one. docs/design.md ("ESDF").
#include <cstdint>
#include <memory>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox::integrators {

struct EsdfIntegratorConfig {
  // Distances are exact up to this and clamped to it beyond (voxblox's default 2 m).
  float esdf_max_distance_m = 2.0f;
  // A voxel is a surface site when |TSDF| <= this many voxels (and it is observed).
  float site_distance_threshold_vox = 1.0f;
  // Voxels with less TSDF weight are unobserved.
  float min_weight = 1e-4f;
  // Refuse windows larger than this many voxels (memory: about 16 bytes each).
  int64_t max_window_voxels = 400000000;
};

struct EsdfUpdateStats {
  int64_t changed_blocks = 0;
  int64_t window_voxels = 0;
  int64_t voxels_written = 0;
};

class EsdfIntegrator {
 public:
  explicit EsdfIntegrator(const EsdfIntegratorConfig& config);
  ~EsdfIntegrator();
  EsdfIntegrator(EsdfIntegrator&&) noexcept;
  EsdfIntegrator& operator=(EsdfIntegrator&&) noexcept;

  const EsdfIntegratorConfig& config() const { return config_; }

  // Recomputes the ESDF around blocks whose TSDF changed since the last update.
  EsdfUpdateStats update(map::TsdfMap& map, const Stream& stream);
  // Recomputes the ESDF of the whole map.
  EsdfUpdateStats update_all(map::TsdfMap& map, const Stream& stream);

 private:
  struct Scratch;
  EsdfUpdateStats run(map::TsdfMap& map, bool all_blocks, const Stream& stream);
  EsdfIntegratorConfig config_;
  std::unique_ptr<Scratch> scratch_;
};

// Pieces shared by the backend instantiations.
struct EsdfScratchBuffers {
  explicit EsdfScratchBuffers(Device device)
      : block_indices(device),
        block_slots(device),
        squared(device),
        squared_tmp(device),
        envelope_sites(device),
        envelope_bounds(device) {}
  Buffer<Index3D> block_indices;
  Buffer<uint32_t> block_slots;
  Buffer<int32_t> squared;  // squared distance in voxels^2 over the window
  Buffer<int32_t> squared_tmp;
  Buffer<int32_t> envelope_sites;
  Buffer<double> envelope_bounds;
};

template <class Backend>
EsdfUpdateStats esdf_update(Backend backend, const EsdfIntegratorConfig& config, map::TsdfMap& map,
                            bool all_blocks, EsdfScratchBuffers& scratch, const Stream& stream);

}  // namespace covox::integrators

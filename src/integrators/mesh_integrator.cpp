#include "covoxslam/integrators/mesh_integrator.h"

#include <map>
#include <vector>

#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/integrators/pending_block_meshes.h"

namespace covox::integrators {

struct MeshIntegrator::Scratch {
  explicit Scratch(Device device) : buffers(device) {}
  MeshScratchBuffers buffers;
};

MeshIntegrator::MeshIntegrator(const MeshIntegratorConfig& config) : config_(config) {}
MeshIntegrator::~MeshIntegrator() = default;
MeshIntegrator::MeshIntegrator(MeshIntegrator&&) noexcept = default;
MeshIntegrator& MeshIntegrator::operator=(MeshIntegrator&&) noexcept = default;

map::Mesh MeshIntegrator::extract_all(map::TsdfMap& map, const Stream& stream) {
  if (!scratch_ || scratch_->buffers.blocks.device() != map.device())
    scratch_ = std::make_unique<Scratch>(map.device());
  MeshScratchBuffers& scratch = scratch_->buffers;
  map.blocks().export_entries(&scratch.blocks, &scratch.counts);
  int64_t vertex_count = 0;
  const int64_t triangles = dispatch(map.device(), [&](auto backend) {
    return mesh_extract(backend, map, config_.min_weight, MeshWeld::kGlobal, scratch, &vertex_count,
                        stream, config_.max_weld_table_entries);
  });
  map::Mesh mesh;
  if (triangles == 0) return mesh;
  mesh.vertices_m = scratch.vertices.to_host(stream);
  mesh.colors = scratch.vertex_colors.to_host(stream);
  mesh.triangles = scratch.triangles.to_host(stream);
  return mesh;
}

MeshUpdateStats MeshIntegrator::update(map::TsdfMap& map, const Stream& stream) {
  if (!scratch_ || scratch_->buffers.blocks.device() != map.device())
    scratch_ = std::make_unique<Scratch>(map.device());
  if (!pending_) pending_ = std::make_unique<PendingBlockMeshes>(map.device());
  MeshScratchBuffers& scratch = scratch_->buffers;
  StageProfiler::Scope profile("mesh update", stream);
  MeshUpdateStats stats;
  int64_t vertex_count = 0;
  dispatch(map.device(), [&](auto backend) {
    stats.blocks_meshed = mesh_select_blocks(backend, map, scratch, stream);
    profile.mark("select blocks");
    stats.triangles = mesh_extract(backend, map, config_.min_weight, MeshWeld::kPerBlock, scratch,
                                   &vertex_count, stream, config_.max_weld_table_entries);
    profile.mark("extract (per-block weld)");
  });
  pending_->append(scratch, vertex_count, stats.triangles, stream);
  profile.mark("append to the pending block meshes");
  if (pending_->vertex_count() > kMaxPendingVertices) download_pending(stream);
  return stats;
}

void MeshIntegrator::download_pending(const Stream& stream) {
  if (!pending_ || pending_->empty()) return;
  last_updated_ = pending_->apply_to(&block_meshes_, stream);
}

const std::map<Index3D, map::Mesh>& MeshIntegrator::block_meshes(const Stream& stream) {
  download_pending(stream);
  return block_meshes_;
}

const std::vector<Index3D>& MeshIntegrator::last_updated_blocks(const Stream& stream) {
  download_pending(stream);
  return last_updated_;
}

map::Mesh MeshIntegrator::combined_block_meshes(const Stream& stream) {
  map::Mesh combined;
  for (const auto& [block, mesh] : block_meshes(stream)) {
    const uint32_t base = static_cast<uint32_t>(combined.vertices_m.size());
    combined.vertices_m.insert(combined.vertices_m.end(), mesh.vertices_m.begin(),
                               mesh.vertices_m.end());
    combined.colors.insert(combined.colors.end(), mesh.colors.begin(), mesh.colors.end());
    for (uint32_t v : mesh.triangles) combined.triangles.push_back(base + v);
  }
  return combined;
}

}  // namespace covox::integrators

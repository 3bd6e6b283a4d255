#include "covoxslam/integrators/mesh_integrator.h"

#include <set>
#include <unordered_map>

namespace covox {

struct MeshIntegrator::Scratch {
  explicit Scratch(Device device) : buffers(device) {}
  MeshScratchBuffers buffers;
};

MeshIntegrator::MeshIntegrator(const MeshIntegratorConfig& config) : config_(config) {}
MeshIntegrator::~MeshIntegrator() = default;
MeshIntegrator::MeshIntegrator(MeshIntegrator&&) noexcept = default;
MeshIntegrator& MeshIntegrator::operator=(MeshIntegrator&&) noexcept = default;

namespace {

struct Extraction {
  Mesh mesh;
  std::vector<uint32_t> triangle_blocks;
};

Extraction run_extraction(TsdfMap& map, float min_weight, MeshScratchBuffers& scratch, const Stream& stream) {
  int64_t vertex_count = 0;
  const int64_t triangles = dispatch(map.device(), [&](auto backend) {
    return mesh_extract(backend, map, min_weight, scratch, &vertex_count, stream);
  });
  Extraction out;
  if (triangles == 0) return out;
  out.mesh.vertices_m = scratch.vertices.to_host(stream);
  out.mesh.colors = scratch.vertex_colors.to_host(stream);
  out.mesh.triangles = scratch.triangles.to_host(stream);
  out.mesh.triangles.resize(static_cast<size_t>(3 * triangles));
  out.triangle_blocks = scratch.triangle_blocks.to_host(stream);
  return out;
}

}  // namespace

Mesh MeshIntegrator::extract_all(TsdfMap& map, const Stream& stream) {
  if (!scratch_ || scratch_->buffers.blocks.device() != map.device()) scratch_ = std::make_unique<Scratch>(map.device());
  map.blocks().export_entries(&scratch_->buffers.blocks, &scratch_->buffers.slots);
  return run_extraction(map, config_.min_weight, scratch_->buffers, stream).mesh;
}

MeshUpdateStats MeshIntegrator::update(TsdfMap& map, const Stream& stream) {
  if (!scratch_ || scratch_->buffers.blocks.device() != map.device()) scratch_ = std::make_unique<Scratch>(map.device());
  MeshScratchBuffers& scratch = scratch_->buffers;
  map.blocks().export_entries(&scratch.blocks, &scratch.slots);
  const auto blocks = scratch.blocks.to_host(stream);
  const auto slots = scratch.slots.to_host(stream);
  auto changed = map.block_changed().to_host(stream);

  // A cube reads the block of its first corner and the +x/+y/+z neighbours, so a changed block
  // also changes the meshes of the seven blocks just below it.
  const std::set<Index3D> allocated(blocks.begin(), blocks.end());
  std::set<Index3D> affected;
  for (size_t i = 0; i < blocks.size(); ++i) {
    if (!(changed[slots[i]] & kMeshPending)) continue;
    changed[slots[i]] &= static_cast<uint8_t>(~kMeshPending);
    for (int c = 0; c < 8; ++c) {
      const Index3D below = blocks[i] - Index3D(c & 1, (c >> 1) & 1, (c >> 2) & 1);
      if (allocated.count(below)) affected.insert(below);
    }
  }
  last_updated_.assign(affected.begin(), affected.end());
  MeshUpdateStats stats;
  stats.blocks_meshed = static_cast<int64_t>(last_updated_.size());
  if (last_updated_.empty()) return stats;
  map.block_changed().copy_from_host(changed, stream);

  scratch.blocks.copy_from_host(last_updated_, stream);
  const Extraction extraction = run_extraction(map, config_.min_weight, scratch, stream);
  stats.triangles = static_cast<int64_t>(extraction.mesh.triangle_count());
  for (const Index3D& block : last_updated_) block_meshes_.erase(block);
  // Split the welded result into one mesh per block (vertices re-indexed per block).
  std::vector<std::unordered_map<uint32_t, uint32_t>> remap(last_updated_.size());
  for (size_t t = 0; t < extraction.mesh.triangle_count(); ++t) {
    const uint32_t b = extraction.triangle_blocks[t];
    Mesh& mesh = block_meshes_[last_updated_[b]];
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = extraction.mesh.triangles[3 * t + k];
      auto [it, inserted] = remap[b].emplace(v, static_cast<uint32_t>(mesh.vertices_m.size()));
      if (inserted) {
        mesh.vertices_m.push_back(extraction.mesh.vertices_m[v]);
        mesh.colors.push_back(extraction.mesh.colors[v]);
      }
      mesh.triangles.push_back(it->second);
    }
  }
  return stats;
}

Mesh MeshIntegrator::combined_block_meshes() const {
  Mesh combined;
  for (const auto& [block, mesh] : block_meshes_) {
    const uint32_t base = static_cast<uint32_t>(combined.vertices_m.size());
    combined.vertices_m.insert(combined.vertices_m.end(), mesh.vertices_m.begin(), mesh.vertices_m.end());
    combined.colors.insert(combined.colors.end(), mesh.colors.begin(), mesh.colors.end());
    for (uint32_t v : mesh.triangles) combined.triangles.push_back(base + v);
  }
  return combined;
}

}  // namespace covox

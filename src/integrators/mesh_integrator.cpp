#include "covoxslam/integrators/mesh_integrator.h"

#include <map>
#include <vector>

#include "covoxslam/core/stage_profiler.h"

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

// Splits the welded result into one mesh per re-meshed block (vertices re-indexed per block):
// triangles are bucketed by block with a counting sort, and a vertex's index inside the current
// block is remembered in flat arrays (no hashing), so this stays linear and cheap next to the
// extraction itself.
void split_into_block_meshes(const Extraction& extraction, const std::vector<Index3D>& blocks,
                             std::map<Index3D, Mesh>* block_meshes) {
  const size_t block_count = blocks.size();
  const size_t triangle_count = extraction.mesh.triangle_count();
  std::vector<uint32_t> first_triangle(block_count + 1, 0);
  for (size_t t = 0; t < triangle_count; ++t) ++first_triangle[extraction.triangle_blocks[t] + 1];
  for (size_t b = 0; b < block_count; ++b) first_triangle[b + 1] += first_triangle[b];
  std::vector<uint32_t> by_block(triangle_count);
  std::vector<uint32_t> next = first_triangle;
  for (size_t t = 0; t < triangle_count; ++t) by_block[next[extraction.triangle_blocks[t]]++] = static_cast<uint32_t>(t);

  constexpr uint32_t kNone = ~uint32_t(0);
  std::vector<uint32_t> owner(extraction.mesh.vertices_m.size(), kNone);  // block that indexed it last
  std::vector<uint32_t> local_index(extraction.mesh.vertices_m.size());
  const bool has_colors = !extraction.mesh.colors.empty();
  for (size_t b = 0; b < block_count; ++b) {
    if (first_triangle[b + 1] == first_triangle[b]) {
      block_meshes->erase(blocks[b]);
      continue;
    }
    // Refill the block's previous mesh in place: its vectors keep their capacity, so a block that
    // is re-meshed every frame costs no allocation.
    Mesh& mesh = (*block_meshes)[blocks[b]];
    mesh.vertices_m.clear();
    mesh.colors.clear();
    mesh.triangles.clear();
    mesh.triangles.reserve(3 * (first_triangle[b + 1] - first_triangle[b]));
    for (uint32_t i = first_triangle[b]; i < first_triangle[b + 1]; ++i) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = extraction.mesh.triangles[3 * by_block[i] + k];
        if (owner[v] != b) {
          owner[v] = static_cast<uint32_t>(b);
          local_index[v] = static_cast<uint32_t>(mesh.vertices_m.size());
          mesh.vertices_m.push_back(extraction.mesh.vertices_m[v]);
          if (has_colors) mesh.colors.push_back(extraction.mesh.colors[v]);
        }
        mesh.triangles.push_back(local_index[v]);
      }
    }
  }
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
  StageProfiler::Scope profile("mesh update", stream);
  const int64_t selected = dispatch(map.device(), [&](auto backend) {
    return mesh_select_blocks(backend, map, scratch, stream);
  });
  MeshUpdateStats stats;
  stats.blocks_meshed = selected;
  last_updated_ = scratch.blocks.to_host(stream);
  profile.mark("select blocks");
  if (selected == 0) return stats;
  const Extraction extraction = run_extraction(map, config_.min_weight, scratch, stream);
  stats.triangles = static_cast<int64_t>(extraction.mesh.triangle_count());
  profile.mark("extract + download");
  split_into_block_meshes(extraction, last_updated_, &block_meshes_);
  profile.mark("split into block meshes (host)");
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

#include "covoxslam/integrators/pending_block_meshes.h"

#include <algorithm>

#include "covoxslam/core/memory.h"

namespace covox::integrators {

namespace {

// Copies `count` device elements to log[used, used + count), growing the log geometrically (the
// only step that waits for the device, and rarely).
template <class T>
void append_device(Buffer<T>& log, int64_t& used, const T* source, int64_t count,
                   const Stream& stream) {
  if (count <= 0) return;
  if (used + count > static_cast<int64_t>(log.size())) {
    log.resize(static_cast<size_t>(
                   std::max<int64_t>({2 * static_cast<int64_t>(log.size()), used + count, 4096})),
               stream);
  }
  copy_bytes(log.data() + used, log.device(), source, log.device(),
             static_cast<size_t>(count) * sizeof(T), stream);
  used += count;
}

template <class T>
std::vector<T> download_prefix(const Buffer<T>& log, int64_t count, const Stream& stream) {
  std::vector<T> host(static_cast<size_t>(count));
  if (count > 0)
    copy_bytes(host.data(), Device::kCpu, log.data(), log.device(), host.size() * sizeof(T),
               stream);
  return host;
}

}  // namespace

PendingBlockMeshes::PendingBlockMeshes(Device device)
    : vertices_(device),
      colors_(device),
      triangles_(device),
      blocks_(device),
      first_vertex_(device),
      first_triangle_(device) {}

void PendingBlockMeshes::append(const MeshScratchBuffers& extraction, int64_t vertex_count,
                                int64_t triangle_count, const Stream& stream) {
  const int64_t block_count = static_cast<int64_t>(extraction.blocks.size());
  updates_.push_back(
      Update{vertices_used_, triangle_indices_used_ / 3, blocks_used_, ranges_used_, block_count});
  append_device(blocks_, blocks_used_, extraction.blocks.data(), block_count, stream);
  int64_t ranges = ranges_used_;
  append_device(first_vertex_, ranges, extraction.block_first_vertex.data(), block_count + 1,
                stream);
  append_device(first_triangle_, ranges_used_, extraction.block_first_triangle.data(),
                block_count + 1, stream);
  int64_t colors_used = vertices_used_;
  append_device(colors_, colors_used, extraction.vertex_colors.data(), vertex_count, stream);
  append_device(vertices_, vertices_used_, extraction.vertices.data(), vertex_count, stream);
  append_device(triangles_, triangle_indices_used_, extraction.triangles.data(), 3 * triangle_count,
                stream);
}

std::vector<Index3D> PendingBlockMeshes::apply_to(std::map<Index3D, map::Mesh>* block_meshes,
                                                  const Stream& stream) {
  std::vector<Index3D> last_blocks;
  if (updates_.empty()) return last_blocks;
  const std::vector<Vec3f> vertices = download_prefix(vertices_, vertices_used_, stream);
  const std::vector<Rgb8> colors = download_prefix(colors_, vertices_used_, stream);
  const std::vector<uint32_t> triangles =
      download_prefix(triangles_, triangle_indices_used_, stream);
  const std::vector<Index3D> blocks = download_prefix(blocks_, blocks_used_, stream);
  const std::vector<uint32_t> first_vertex = download_prefix(first_vertex_, ranges_used_, stream);
  const std::vector<uint32_t> first_triangle =
      download_prefix(first_triangle_, ranges_used_, stream);
  for (const Update& update : updates_) {
    for (int64_t b = 0; b < update.block_count; ++b) {
      const Index3D block = blocks[update.block_base + b];
      const size_t range = static_cast<size_t>(update.range_base + b);
      const size_t v0 = update.vertex_base + first_vertex[range],
                   v1 = update.vertex_base + first_vertex[range + 1];
      const size_t t0 = update.triangle_base + first_triangle[range];
      const size_t t1 = update.triangle_base + first_triangle[range + 1];
      if (t1 == t0) {
        block_meshes->erase(block);
        continue;
      }
      // assign() refills the block's previous vectors, keeping their capacity.
      map::Mesh& mesh = (*block_meshes)[block];
      mesh.vertices_m.assign(vertices.begin() + v0, vertices.begin() + v1);
      mesh.colors.assign(colors.begin() + v0, colors.begin() + v1);
      mesh.triangles.assign(triangles.begin() + 3 * t0, triangles.begin() + 3 * t1);
    }
  }
  const Update& last = updates_.back();
  last_blocks.assign(blocks.begin() + last.block_base,
                     blocks.begin() + last.block_base + last.block_count);
  updates_.clear();
  vertices_used_ = triangle_indices_used_ = blocks_used_ = ranges_used_ = 0;
  return last_blocks;
}

}  // namespace covox::integrators

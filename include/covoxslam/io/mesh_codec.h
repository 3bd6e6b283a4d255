#pragma once
// The compact form of a triangle mesh: what a finished submap keeps of its mesh once its voxels
// have left the device (pipeline/submap_store.h), in host memory or in the spill file. Every
// vertex coordinate is rounded to the nearest multiple of step_m, so a decoded vertex lies at
// most step_m / 2 (plus the float rounding of the decoded value) from the encoded one; triangle
// indices and colours are exact. The layout: kMeshCodecVersion below.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "covoxslam/map/mesh.h"

namespace covox {
namespace io {

// Layout (little-endian): "CVXM", codec version (u32), step (f32), vertex count (u64), triangle
// count (u64), flags (u8, bit 0: one colour per vertex); the vertices as varints (LEB128) of the
// zigzag-mapped difference of each quantised coordinate from the previous vertex's (x, y, z in
// turn; the first from zero); with colours, n x (r, g, b) bytes; the 3 x triangle count indices
// as varints of the zigzag-mapped difference from the previous index (the first from zero).
// Meshes from marching cubes list neighbouring vertices and triangles together, so most
// differences take one or two bytes.
constexpr uint32_t kMeshCodecVersion = 1;

// Throws covox::Error for a step that is not a positive finite number, colours that are neither
// absent nor one per vertex, an index past the last vertex, or a coordinate whose quantised value
// does not fit 62 bits.
std::vector<uint8_t> encode_mesh(const map::Mesh& mesh, float step_m);

// The mesh of encoded bytes; throws covox::Error saying what is wrong (prefixed with `what`) for
// bytes that are truncated, have trailing bytes, another magic or version, or an index past the
// last vertex.
map::Mesh decode_mesh(const uint8_t* data, size_t size, const char* what);
inline map::Mesh decode_mesh(const std::vector<uint8_t>& bytes, const char* what) {
  return decode_mesh(bytes.data(), bytes.size(), what);
}

// The bytes a mesh takes in memory as map::Mesh holds it (vertices, colours, indices).
size_t mesh_bytes_in_memory(const map::Mesh& mesh);

}  // namespace io
}  // namespace covox

#pragma once
// PLY triangle meshes (ascii and binary_little_endian), e.g. ground-truth meshes such as
// Replica's office0_mesh.ply and the meshes write_mesh_ply (mesh_ply.h) writes. Reads vertex
// x, y, z (any numeric type), vertex red, green, blue when present, and faces as count-prefixed
// index lists ("vertex_indices" or "vertex_index"); polygons with more than three corners are
// split into a triangle fan. Other elements and properties are read past and ignored.
#include <string>

#include "covoxslam/map/mesh.h"

namespace covox {
namespace io {

// Throws covox::Error naming the file for: not a PLY, binary_big_endian, a header without
// vertex x/y/z, truncated data, a non-finite vertex, or a face index out of range.
map::Mesh read_mesh_ply(const std::string& path);

}  // namespace io
}  // namespace covox

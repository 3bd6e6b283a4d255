#pragma once
// Binary little-endian PLY export of a mesh (vertex x y z as float, red green blue as uchar,
// faces as uchar-counted int lists): what rviz-independent viewers (MeshLab, CloudCompare,
// Open3D) read. Written to a temporary file and renamed. Vertices whose colour is black (no fused
// colour or intensity) are written in the colour of their height (map/mesh_colors.h).
#include <ostream>
#include <string>

#include "covoxslam/map/mesh.h"

namespace covox {
namespace io {

void write_mesh_ply(const std::string& path, const map::Mesh& mesh);
// The same PLY into a stream (e.g. io::write_file's, for a checked target).
void write_mesh_ply(std::ostream& file, const map::Mesh& mesh);

}  // namespace io
}  // namespace covox

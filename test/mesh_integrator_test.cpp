// Marching cubes against analytic surfaces: vertex accuracy, watertightness, orientation,
// incremental updates, CPU vs CUDA.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <utility>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/io/mesh_ply.h"
#include "support/analytic_tsdf.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::DeviceTest;

constexpr float kVoxel = 0.05f;
const Eigen::Vector3d kCentre(0.013, -0.021, 0.007);

double sphere_sdf(const Eigen::Vector3d& p) { return (p - kCentre).norm() - 0.4; }
double small_sphere_sdf(const Eigen::Vector3d& p) { return (p - kCentre).norm() - 0.17; }
const Eigen::Vector3d kBoxHalfExtent(0.33, 0.27, 0.21);
double box_sdf(const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = (p - kCentre).cwiseAbs() - kBoxHalfExtent;
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}
// Distance from a point on the box surface to the nearest of its 12 edges (sharp features).
double distance_to_box_edge(const Eigen::Vector3d& p) {
  const Eigen::Vector3d gap =
      (kBoxHalfExtent - (p - kCentre).cwiseAbs()).cwiseAbs();  // to each face plane
  // An edge is where two face planes meet: the second-smallest gap bounds the distance to it.
  double g[3] = {gap.x(), gap.y(), gap.z()};
  std::sort(g, g + 3);
  return std::hypot(g[0], g[1]);
}

// Every undirected edge used by exactly two triangles, and in opposite directions (consistent
// orientation).
void expect_closed_and_consistent(const map::Mesh& mesh) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    for (int k = 0; k < 3; ++k) {
      directed[{mesh.triangles[3 * t + k], mesh.triangles[3 * t + (k + 1) % 3]}]++;
    }
  }
  int open_edges = 0, inconsistent = 0;
  for (const auto& [edge, count] : directed) {
    const auto reverse = directed.find({edge.second, edge.first});
    if (reverse == directed.end())
      ++open_edges;
    else if (count != 1 || reverse->second != 1)
      ++inconsistent;
  }
  EXPECT_EQ(open_edges, 0);
  EXPECT_EQ(inconsistent, 0);
}

map::Mesh mesh_of(Device device, double (*sdf)(const Eigen::Vector3d&)) {
  map::TsdfMap map(device, map::TsdfMapConfig{kVoxel, 8, {}});
  testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7), Eigen::Vector3d(0.7, 0.7, 0.7),
                             4 * kVoxel, sdf);
  integrators::MeshIntegrator integrator;
  return integrator.extract_all(map, Stream(device));
}

class MeshIntegratorTest : public DeviceTest {};

TEST_P(MeshIntegratorTest, SphereAndBoxVerticesLieOnTheSurfaceAndMeshesAreClosed) {
  for (auto* sdf : {&sphere_sdf, &box_sdf}) {
    const map::Mesh mesh = mesh_of(device(), sdf);
    ASSERT_GT(mesh.triangle_count(), 1000u);
    // Marching cubes interpolates linearly between samples, which is exact on smooth surfaces but
    // cannot reproduce a sharp edge: on the box, vertices within a voxel of an edge are allowed
    // 0.2 voxel, all others 0.1 voxel.
    double worst_smooth = 0.0, worst_near_edges = 0.0;
    for (const Vec3f& v : mesh.vertices_m) {
      const Eigen::Vector3d p(v.x, v.y, v.z);
      const double error = std::abs(sdf(p));
      if (sdf == &box_sdf && distance_to_box_edge(p) < kVoxel) {
        worst_near_edges = std::max(worst_near_edges, error);
      } else {
        worst_smooth = std::max(worst_smooth, error);
      }
    }
    EXPECT_LT(worst_smooth, 0.1 * kVoxel);
    EXPECT_LT(worst_near_edges, 0.2 * kVoxel);
    expect_closed_and_consistent(mesh);
    // Normals point out of the solid (towards positive distance).
    int outward = 0;
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
      const Vec3f a = mesh.vertices_m[mesh.triangles[3 * t]],
                  b = mesh.vertices_m[mesh.triangles[3 * t + 1]],
                  c = mesh.vertices_m[mesh.triangles[3 * t + 2]];
      const Eigen::Vector3d u(b.x - a.x, b.y - a.y, b.z - a.z), w(c.x - a.x, c.y - a.y, c.z - a.z);
      const Eigen::Vector3d centroid((a.x + b.x + c.x) / 3, (a.y + b.y + c.y) / 3,
                                     (a.z + b.z + c.z) / 3);
      outward += u.cross(w).dot(centroid - kCentre) > 0;
    }
    EXPECT_EQ(outward, static_cast<int>(mesh.triangle_count()));
    EXPECT_EQ(mesh.colors.size(), mesh.vertices_m.size());
  }
}

// The block of the cube a triangle came from: its centroid lies inside the cube, whose first
// corner is the voxel centre just below the centroid.
Index3D block_of_triangle(const map::Mesh& mesh, size_t t, int side) {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) {
    const Vec3f& v = mesh.vertices_m[mesh.triangles[3 * t + k]];
    centroid += Eigen::Vector3d(v.x, v.y, v.z) / 3.0;
  }
  const Eigen::Vector3d cube = (centroid / kVoxel - Eigen::Vector3d::Constant(0.5)).array().floor();
  return Index3D(floor_divide(static_cast<int32_t>(cube.x()), side),
                 floor_divide(static_cast<int32_t>(cube.y()), side),
                 floor_divide(static_cast<int32_t>(cube.z()), side));
}

using TriangleCorners = std::array<float, 9>;
// The triangles of `mesh` as corner positions (so meshes with different vertex numbering compare).
std::vector<TriangleCorners> corner_triangles(const map::Mesh& mesh,
                                              const std::vector<size_t>& which) {
  std::vector<TriangleCorners> out;
  for (size_t t : which) {
    TriangleCorners c;
    for (int k = 0; k < 3; ++k) {
      const Vec3f& v = mesh.vertices_m[mesh.triangles[3 * t + k]];
      c[3 * k] = v.x, c[3 * k + 1] = v.y, c[3 * k + 2] = v.z;
    }
    out.push_back(c);
  }
  std::sort(out.begin(), out.end());
  return out;
}
std::vector<size_t> all_triangles(const map::Mesh& mesh) {
  std::vector<size_t> all(mesh.triangle_count());
  for (size_t t = 0; t < all.size(); ++t) all[t] = t;
  return all;
}

// Each block mesh of the incremental path holds exactly the triangles of the full (globally
// welded) extraction whose cubes lie in that block, its vertices are each used, and none repeats.
void expect_block_meshes_match(const std::map<Index3D, map::Mesh>& block_meshes,
                               const map::Mesh& full, int side) {
  std::map<Index3D, std::vector<size_t>> by_block;
  for (size_t t = 0; t < full.triangle_count(); ++t)
    by_block[block_of_triangle(full, t, side)].push_back(t);
  ASSERT_EQ(block_meshes.size(), by_block.size());
  for (const auto& [block, triangles] : by_block) {
    const auto it = block_meshes.find(block);
    ASSERT_NE(it, block_meshes.end()) << "block " << block.x << " " << block.y << " " << block.z;
    const map::Mesh& mesh = it->second;
    EXPECT_EQ(corner_triangles(mesh, all_triangles(mesh)), corner_triangles(full, triangles));
    ASSERT_EQ(mesh.colors.size(), mesh.vertices_m.size());
    std::vector<int> uses(mesh.vertices_m.size(), 0);
    for (uint32_t v : mesh.triangles) {
      ASSERT_LT(v, mesh.vertices_m.size());
      ++uses[v];
    }
    EXPECT_EQ(std::count(uses.begin(), uses.end(), 0), 0);
    std::vector<std::array<float, 3>> positions;
    for (const Vec3f& v : mesh.vertices_m) positions.push_back({v.x, v.y, v.z});
    std::sort(positions.begin(), positions.end());
    EXPECT_EQ(std::adjacent_find(positions.begin(), positions.end()), positions.end())
        << "a vertex is not welded";
  }
}

TEST_P(MeshIntegratorTest, IncrementalBlockMeshesMatchTheFullExtraction) {
  map::TsdfMap map(device(), map::TsdfMapConfig{kVoxel, 8, {}});
  testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7), Eigen::Vector3d(0.7, 0.7, 0.7),
                             4 * kVoxel, sphere_sdf);
  integrators::MeshIntegrator integrator;
  const Stream stream(device());
  const integrators::MeshUpdateStats first = integrator.update(map, stream);
  EXPECT_EQ(first.blocks_meshed, map.block_count());
  EXPECT_EQ(static_cast<int64_t>(integrator.last_updated_blocks(stream).size()), map.block_count());
  const map::Mesh sphere = integrator.extract_all(map, stream);
  EXPECT_EQ(integrator.combined_block_meshes(stream).triangle_count(), sphere.triangle_count());
  EXPECT_EQ(first.triangles, static_cast<int64_t>(sphere.triangle_count()));
  expect_block_meshes_match(integrator.block_meshes(stream), sphere, 8);
  EXPECT_EQ(integrator.update(map, stream).blocks_meshed, 0);  // nothing changed
  EXPECT_TRUE(integrator.last_updated_blocks(stream).empty());
  // Replace the sphere by the box, then by a smaller sphere, without reading the block meshes in
  // between: the pending updates are replayed in order, and blocks left empty lose their mesh.
  testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7), Eigen::Vector3d(0.7, 0.7, 0.7),
                             4 * kVoxel, box_sdf);
  integrator.update(map, stream);
  const map::Mesh box = integrator.extract_all(map, stream);
  EXPECT_EQ(integrator.combined_block_meshes(stream).triangle_count(), box.triangle_count());
  expect_block_meshes_match(integrator.block_meshes(stream), box, 8);
  testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7), Eigen::Vector3d(0.7, 0.7, 0.7),
                             4 * kVoxel, sphere_sdf);
  integrator.update(map, stream);
  testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7), Eigen::Vector3d(0.7, 0.7, 0.7),
                             4 * kVoxel, small_sphere_sdf);
  integrator.update(map, stream);
  expect_block_meshes_match(integrator.block_meshes(stream), integrator.extract_all(map, stream),
                            8);
}

// The two per-block welds (edge table, sorted keys) number vertices the same way.
TEST_P(MeshIntegratorTest, WeldTableAndSortedWeldGiveTheSameBlockMeshes) {
  map::TsdfMap map(device(), map::TsdfMapConfig{kVoxel, 8, {}});
  testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7), Eigen::Vector3d(0.7, 0.7, 0.7),
                             4 * kVoxel, box_sdf);
  const Stream stream(device());
  integrators::MeshIntegratorConfig sorted_config;
  sorted_config.max_weld_table_entries = 0;
  integrators::MeshIntegrator with_table, with_sort(sorted_config);
  with_table.update(map, stream);
  testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7), Eigen::Vector3d(0.7, 0.7, 0.7),
                             4 * kVoxel,
                             box_sdf);  // pending again for the second integrator
  with_sort.update(map, stream);
  const auto& a = with_table.block_meshes(stream);
  const auto& b = with_sort.block_meshes(stream);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_FALSE(a.empty());
  for (const auto& [block, mesh] : a) {
    const map::Mesh& other = b.at(block);
    EXPECT_EQ(mesh.triangles, other.triangles);
    ASSERT_EQ(mesh.vertices_m.size(), other.vertices_m.size());
    for (size_t i = 0; i < mesh.vertices_m.size(); ++i) {
      EXPECT_EQ(mesh.vertices_m[i].x, other.vertices_m[i].x);
      EXPECT_EQ(mesh.vertices_m[i].y, other.vertices_m[i].y);
      EXPECT_EQ(mesh.vertices_m[i].z, other.vertices_m[i].z);
    }
  }
}

// The same blocks inserted in the opposite order into a nearly full table end in other buckets
// (linear probing keeps the first insert of colliding keys in the home bucket); the whole-map
// mesh must not follow the table's layout (it is written to files and compared between runs).
TEST_P(MeshIntegratorTest, WholeMapMeshDoesNotDependOnTheHashTableLayout) {
  map::TsdfMap filled(device(), map::TsdfMapConfig{kVoxel, 8, {}});
  testing_support::fill_tsdf(filled, Eigen::Vector3d(-0.7, -0.7, -0.7),
                             Eigen::Vector3d(0.7, 0.7, 0.7), 4 * kVoxel, box_sdf);
  std::vector<map::HostBlock> blocks = filled.snapshot();
  ASSERT_GT(blocks.size(), 50u);
  map::TsdfMapConfig crowded{kVoxel, 8, {}};
  crowded.block_table.initial_bucket_count = blocks.size() + 2;
  crowded.block_table.max_load_factor = 0.99;
  const Stream stream(device());
  map::TsdfMap forward(device(), crowded), backward(device(), crowded);
  forward.load_blocks(blocks, stream);
  std::reverse(blocks.begin(), blocks.end());
  backward.load_blocks(blocks, stream);
  Buffer<Index3D> forward_order(device()), backward_order(device());
  Buffer<uint32_t> slots(device());
  forward.blocks().export_entries(&forward_order, &slots);
  backward.blocks().export_entries(&backward_order, &slots);
  ASSERT_NE(forward_order.to_host(stream), backward_order.to_host(stream))
      << "both tables hold the blocks in the same order: the test shows nothing";

  const map::Mesh a = integrators::MeshIntegrator().extract_all(forward, stream);
  const map::Mesh b = integrators::MeshIntegrator().extract_all(backward, stream);
  ASSERT_GT(a.triangle_count(), 100u);
  EXPECT_EQ(a.triangles, b.triangles);
  ASSERT_EQ(a.vertices_m.size(), b.vertices_m.size());
  EXPECT_EQ(0, std::memcmp(a.vertices_m.data(), b.vertices_m.data(),
                           a.vertices_m.size() * sizeof(Vec3f)));
}

TEST_P(MeshIntegratorTest, BinaryPlyHoldsEveryVertexAndFace) {
  const map::Mesh mesh = mesh_of(device(), &sphere_sdf);
  const std::string path = ::testing::TempDir() + "/covox_sphere.ply";
  io::write_mesh_ply(path, mesh);
  std::ifstream file(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  const std::string header_end = "end_header\n";
  const size_t body = bytes.find(header_end) + header_end.size();
  ASSERT_NE(bytes.find("element vertex " + std::to_string(mesh.vertices_m.size()) + "\n"),
            std::string::npos);
  ASSERT_NE(bytes.find("element face " + std::to_string(mesh.triangle_count()) + "\n"),
            std::string::npos);
  // Body size: 15 bytes per coloured vertex, 13 per triangle.
  ASSERT_EQ(bytes.size() - body, mesh.vertices_m.size() * 15 + mesh.triangle_count() * 13);
  float first[3];
  std::memcpy(first, bytes.data() + body, sizeof(first));
  EXPECT_EQ(first[0], mesh.vertices_m[0].x);
  int32_t last_face[3];
  std::memcpy(last_face, bytes.data() + bytes.size() - 12, sizeof(last_face));
  EXPECT_EQ(static_cast<uint32_t>(last_face[2]), mesh.triangles.back());
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(MeshIntegratorTest);

TEST(MeshIntegratorParity, CpuAndCudaGiveTheSameMesh) {
  COVOX_SKIP_WITHOUT_GPU();
  const map::Mesh cpu = mesh_of(Device::kCpu, &sphere_sdf);
  const map::Mesh gpu = mesh_of(Device::kCuda, &sphere_sdf);
  ASSERT_EQ(cpu.triangles, gpu.triangles);
  ASSERT_EQ(cpu.vertices_m.size(), gpu.vertices_m.size());
  for (size_t i = 0; i < cpu.vertices_m.size(); ++i) {
    ASSERT_NEAR(cpu.vertices_m[i].x, gpu.vertices_m[i].x, 1e-6f);
    ASSERT_NEAR(cpu.vertices_m[i].y, gpu.vertices_m[i].y, 1e-6f);
    ASSERT_NEAR(cpu.vertices_m[i].z, gpu.vertices_m[i].z, 1e-6f);
  }
}

TEST(MeshIntegratorParity, CpuAndCudaGiveTheSameBlockMeshes) {
  COVOX_SKIP_WITHOUT_GPU();
  std::map<Index3D, map::Mesh> meshes[2];
  const Device devices[2] = {Device::kCpu, Device::kCuda};
  for (int d = 0; d < 2; ++d) {
    map::TsdfMap map(devices[d], map::TsdfMapConfig{kVoxel, 8, {}});
    testing_support::fill_tsdf(map, Eigen::Vector3d(-0.7, -0.7, -0.7),
                               Eigen::Vector3d(0.7, 0.7, 0.7), 4 * kVoxel, box_sdf);
    integrators::MeshIntegrator integrator;
    const Stream stream = Stream::create(devices[d]);
    integrator.update(map, stream);
    meshes[d] = integrator.block_meshes(stream);
  }
  ASSERT_EQ(meshes[0].size(), meshes[1].size());
  for (const auto& [block, cpu] : meshes[0]) {
    const map::Mesh& gpu = meshes[1].at(block);
    ASSERT_EQ(cpu.triangles, gpu.triangles);
    ASSERT_EQ(cpu.colors.size(), gpu.colors.size());
    ASSERT_EQ(cpu.vertices_m.size(), gpu.vertices_m.size());
    for (size_t i = 0; i < cpu.vertices_m.size(); ++i) {
      ASSERT_NEAR(cpu.vertices_m[i].x, gpu.vertices_m[i].x, 1e-6f);
      ASSERT_NEAR(cpu.vertices_m[i].y, gpu.vertices_m[i].y, 1e-6f);
      ASSERT_NEAR(cpu.vertices_m[i].z, gpu.vertices_m[i].z, 1e-6f);
    }
  }
}

}  // namespace
}  // namespace covox

// surface_bias: each submap's TSDF against the exact signed distance of the simulated world.
//
// Input: a map saved by `run_slam --map`, the same run's `--graph` dump (each submap's first and
// last scan stamps), the flight's true sensor poses and simulate_flight's world.ply (its
// triangles face outwards). Each submap is placed at its true pose at its first scan, gravity
// aligned, as registration_accuracy places it; each observed voxel's centre gets the signed
// distance to the nearest world triangle (positive outside), where that nearest point lies inside
// a triangle (edges and corners of overlapping primitives give no reliable sign).
//
// Output: the stored distance and its error (stored - true) binned by the true distance, for all
// voxels, for ground (true normal within 45 degrees of up) and for walls that face the submap's
// middle position. Where the error changes sign tells where the zero crossing lies; the slope of
// the stored distance against the true one is the projective stretch.
//
// `--write-map FILE --replace all|same-sign|other-sign|ground` writes the map with the stored
// distances of the chosen observed voxels replaced by the true ones (clamped to the truncation),
// weights and observed voxels unchanged: registration_accuracy on that file tells which errors of
// the TSDF make the registrations' bias. same-sign: only voxels whose stored and true distance
// agree in sign (the projective stretch); other-sign: the rest (sides a submap did not see, such
// as the far face of a wall thinner than the truncation); ground: same-sign on the ground.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cli/command_line.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/map_file.h"
#include "covoxslam/io/ply_reader.h"
#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/map/block_voxel_indexer.h"
#include "covoxslam/pipeline/submap.h"
#include "eval/mesh_distance.h"
#include "eval/submap_truth.h"

using namespace covox;

namespace {

const char* kUsage =
    "usage: surface_bias --map FILE --graph FILE --truth FILE.tum --world world.ply [options]\n"
    "  --truncation-m T   the run's TSDF truncation (default 0.6, the arche preset)\n"
    "  --write-map FILE   the map with true distances in place of the stored ones\n"
    "  --replace WHICH    which voxels --write-map replaces: all (default), same-sign (stored\n"
    "                     and true distance agree in sign), other-sign (they do not) or ground\n"
    "                     (same-sign on the ground)\n";

struct Triangle {
  Eigen::Vector3d a, b, c, normal;
};

// Whether q, a point of triangle t's plane, lies inside the face rather than on an edge or a
// corner (its barycentric coordinates all positive).
bool inside_face(const Triangle& t, const Eigen::Vector3d& q) {
  const double area = t.normal.dot((t.b - t.a).cross(t.c - t.a));
  const double u = t.normal.dot((t.c - t.b).cross(q - t.b)) / area;
  const double v = t.normal.dot((t.a - t.c).cross(q - t.c)) / area;
  return u > 1e-9 && v > 1e-9 && 1.0 - u - v > 1e-9;
}

// The nearest world triangle of a point: its signed distance, outward normal and whether the
// nearest point is inside the face.
struct Nearest {
  double distance_m = 0.0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  bool interior = false;
};

// Triangles binned in cubes of 1 m: a triangle goes into every cube its box, grown by
// `reach_m`, touches, so a cube lists every triangle within reach_m of any point in it.
class TriangleGrid {
 public:
  TriangleGrid(const map::Mesh& mesh, double reach_m) {
    const auto vertex = [&](uint32_t i) {
      const Vec3f& p = mesh.vertices_m.at(i);
      return Eigen::Vector3d(p.x, p.y, p.z);
    };
    for (size_t k = 0; k + 2 < mesh.triangles.size(); k += 3) {
      Triangle t{vertex(mesh.triangles[k]), vertex(mesh.triangles[k + 1]),
                 vertex(mesh.triangles[k + 2]), Eigen::Vector3d::Zero()};
      const Eigen::Vector3d n = (t.b - t.a).cross(t.c - t.a);
      if (n.norm() < 1e-12) continue;  // degenerate: no face
      t.normal = n.normalized();
      const uint32_t index = static_cast<uint32_t>(triangles_.size());
      triangles_.push_back(t);
      const Eigen::Vector3d low = t.a.cwiseMin(t.b).cwiseMin(t.c).array() - reach_m;
      const Eigen::Vector3d high = t.a.cwiseMax(t.b).cwiseMax(t.c).array() + reach_m;
      for (int64_t x = cube(low.x()); x <= cube(high.x()); ++x)
        for (int64_t y = cube(low.y()); y <= cube(high.y()); ++y)
          for (int64_t z = cube(low.z()); z <= cube(high.z()); ++z)
            cubes_[key(x, y, z)].push_back(index);
    }
  }

  // False when no triangle lies within reach of p's cube.
  bool nearest(const Eigen::Vector3d& p, Nearest* out) const {
    const auto found = cubes_.find(key(cube(p.x()), cube(p.y()), cube(p.z())));
    if (found == cubes_.end()) return false;
    double best = std::numeric_limits<double>::infinity();
    for (uint32_t index : found->second) {
      const Triangle& t = triangles_[index];
      const Eigen::Vector3d q = eval::closest_point_on_triangle(p, t.a, t.b, t.c);
      const double d = (p - q).norm();
      if (d >= best) continue;
      best = d;
      out->normal = t.normal;
      out->interior = inside_face(t, q);
      out->distance_m = (p - q).dot(t.normal) >= 0 ? d : -d;
    }
    return true;
  }

 private:
  static int64_t cube(double v) { return static_cast<int64_t>(std::floor(v)); }
  static int64_t key(int64_t x, int64_t y, int64_t z) {
    return ((x + 100000) * 200000 + (y + 100000)) * 4096 + (z + 2048);
  }
  std::vector<Triangle> triangles_;
  std::map<int64_t, std::vector<uint32_t>> cubes_;
};

// Sums of one class of voxels binned by true distance: -0.7 m to 0.7 m in 0.1 m bins.
struct Profile {
  static constexpr int kBins = 14;
  double count[kBins] = {}, stored[kBins] = {}, error[kBins] = {}, squared[kBins] = {};

  void add(double truth_m, double stored_m) {
    const int bin = static_cast<int>(std::floor((truth_m + 0.7) / 0.1));
    if (bin < 0 || bin >= kBins) return;
    count[bin] += 1;
    stored[bin] += stored_m;
    error[bin] += stored_m - truth_m;
    squared[bin] += (stored_m - truth_m) * (stored_m - truth_m);
  }
};

struct Profiles {
  Profile all, ground, facing_walls;
};

// One submap's voxel: its stored TSDF voxel and its centre in the world.
template <class Visit>
void for_each_observed_voxel(io::SubmapRecord& record, const Eigen::Isometry3d& T_world_submap,
                             float voxel_m, int side, Visit&& visit) {
  for (map::HostBlock& block : record.blocks) {
    for (size_t k = 0; k < block.tsdf.size(); ++k) {
      map::TsdfVoxel& voxel = block.tsdf[k];
      if (!(voxel.weight > 1e-4f)) continue;
      const Index3D g = map::global_voxel(block.index, static_cast<int64_t>(k), side);
      const Eigen::Vector3d centre_submap =
          (Eigen::Vector3d(g.x, g.y, g.z).array() + 0.5).matrix() * static_cast<double>(voxel_m);
      visit(voxel, T_world_submap * centre_submap);
    }
  }
}

enum class Replace { kAll, kSameSign, kOtherSign, kGround };

Replace parse_replace(const std::string& text) {
  if (text == "all") return Replace::kAll;
  if (text == "same-sign") return Replace::kSameSign;
  if (text == "other-sign") return Replace::kOtherSign;
  if (text == "ground") return Replace::kGround;
  throw Error("--replace must be all, same-sign, other-sign or ground, got '" + text + "'");
}

bool is_ground(const Nearest& n) { return n.normal.z() > std::sqrt(0.5); }

bool replaces(Replace which, const Nearest& n, float stored_m) {
  const bool same_sign = (stored_m < 0) == (n.distance_m < 0);
  if (which == Replace::kSameSign) return same_sign;
  if (which == Replace::kOtherSign) return !same_sign;
  if (which == Replace::kGround) return same_sign && is_ground(n);
  return true;
}

struct Options {
  std::string map_path, graph_path, truth_path, world_path, write_path;
  double truncation_m = 0.6;
  Replace replace = Replace::kAll;
};

Options parse_options(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  Options o;
  o.map_path = args.text("--map", "");
  o.graph_path = args.text("--graph", "");
  o.truth_path = args.text("--truth", "");
  o.world_path = args.text("--world", "");
  o.write_path = args.text("--write-map", "");
  o.truncation_m = args.number("--truncation-m", 0.6, 0.01, 100.0);
  const std::string replace = args.text("--replace", "all");
  args.finish();
  if (o.map_path.empty() || o.graph_path.empty() || o.truth_path.empty() || o.world_path.empty())
    args.fail("--map, --graph, --truth and --world are required");
  try {
    o.replace = parse_replace(replace);
  } catch (const Error& error) {
    args.fail(error.what());
  }
  return o;
}

void print_profile(const char* name, const Profile& p) {
  std::printf("%s\ntrue_m      voxels  stored_m   error_m     rms_m\n", name);
  for (int b = 0; b < Profile::kBins; ++b) {
    if (p.count[b] == 0) continue;
    std::printf("%+5.2f %12.0f %+9.3f %+9.3f %9.3f\n", -0.65 + 0.1 * b, p.count[b],
                p.stored[b] / p.count[b], p.error[b] / p.count[b],
                std::sqrt(p.squared[b] / p.count[b]));
  }
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse_options(argc, argv);
  try {
    io::MapFileContents contents = io::load_map_file(o.map_path);
    const std::map<int64_t, eval::SubmapSpan> spans = eval::read_submap_spans(o.graph_path);
    const io::Trajectory truth = io::read_tum_trajectory(o.truth_path);
    // Every triangle within the truncation and a voxel's half diagonal of a cube's points.
    const TriangleGrid grid(io::read_mesh_ply(o.world_path), o.truncation_m + 0.5);
    Profiles profiles;
    for (io::SubmapRecord& record : contents.submaps) {
      const auto span = spans.find(record.id);
      if (span == spans.end())
        throw Error("submap " + std::to_string(record.id) + " is not in " + o.graph_path);
      const Eigen::Isometry3d T = pipeline::to_isometry(pipeline::pose_4dof_from_isometry(
          eval::true_pose_at(truth, span->second.start_s, o.truth_path)));
      const Eigen::Vector3d middle =
          eval::true_pose_at(truth, 0.5 * (span->second.start_s + span->second.end_s), o.truth_path)
              .translation();
      for_each_observed_voxel(
          record, T, contents.voxel_size_m, contents.voxels_per_side,
          [&](map::TsdfVoxel& voxel, const Eigen::Vector3d& centre) {
            Nearest n;
            if (!grid.nearest(centre, &n) || !n.interior) return;
            profiles.all.add(n.distance_m, voxel.distance_m);
            if (is_ground(n)) profiles.ground.add(n.distance_m, voxel.distance_m);
            if (std::abs(n.normal.z()) < 0.3 && n.normal.dot(middle - centre) > 0)
              profiles.facing_walls.add(n.distance_m, voxel.distance_m);
            if (!o.write_path.empty() && replaces(o.replace, n, voxel.distance_m)) {
              voxel.distance_m =
                  static_cast<float>(std::clamp(n.distance_m, -o.truncation_m, o.truncation_m));
            }
          });
    }
    print_profile("all observed voxels", profiles.all);
    print_profile("ground", profiles.ground);
    print_profile("walls facing the submap's middle position", profiles.facing_walls);
    if (!o.write_path.empty()) io::save_map_file(o.write_path, contents);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "surface_bias: %s\n", error.what());
    return 1;
  }
  return 0;
}

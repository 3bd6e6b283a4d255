// registration_accuracy: how close submap-to-submap registration lands to the true relative pose
// when it starts there (or a known distance away). It separates the registration's own bias
// from the graph's: on a flight whose odometry equals the truth (`simulate_flight --drift-scale
// 0`) a perfect registration would return the true relative pose for every pair.
//
// Input: a map saved by `run_slam --map` (submap voxels and ESDF), the same run's `--graph` dump
// (each submap's first-scan stamp) and the flight's true sensor poses (TUM). Each submap is
// placed at its true pose (gravity aligned) and registered to every earlier submap it overlaps,
// exactly as the SLAM system does (pipeline::registration_constraints: coarse-to-fine levels,
// symmetric solve, acceptance tests), with the registration settings of the arche_sim preset and an
// optional `--config` file over it. With `--start-offset-m D` the new submap starts D metres
// from its true position, in a direction that turns by the golden angle from one submap to the
// next, and `--start-yaw-deg A` adds a yaw error of alternating sign: the basin, not just the bias.
// `--repeat N` aligns each accepted pair N more times, each from the last result (whether a
// re-registration from a corrected pose would converge further).
//
// Output: one row per accepted constraint (translation and yaw error against the truth) and the
// medians for neighbours (ids at most `--neighbour-gap` apart) and revisits, with the mean signed
// error along the true relative translation (`along_m`; negative: the pair drawn together) and
// its sum over the sum of the pairs' lengths (`scale_%`): a bias there is a scale error of the
// trajectory. `--walls` adds the top-view wall match alone (pipeline/wall_map.h) of every
// overlapping revisit pair, started where the registration starts.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "command_line.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/io/map_file.h"
#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/pipeline/registration_constraints.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "covoxslam/pipeline/submap.h"
#include "covoxslam/pipeline/submap_pose_graph.h"
#include "covoxslam/pipeline/wall_map.h"
#include "slam_run.h"
#include "trajectory_evaluation.h"

using namespace covox;

namespace {

const char* kUsage =
    "usage: registration_accuracy --map FILE --graph FILE --truth FILE.tum [options]\n"
    "  --map FILE             map saved by run_slam --map (submaps with their ESDF)\n"
    "  --graph FILE           the same run's run_slam --graph dump (submap first-scan stamps)\n"
    "  --truth FILE.tum       true sensor poses (simulate_flight's truth.tum)\n"
    "  --config FILE.yaml     a configuration file over the arche_sim preset (only registration "
    "matters)\n"
    "  --device auto|cpu|cuda (default auto)\n"
    "  --start-offset-m D     start each new submap D m from its true position (default 0)\n"
    "  --start-yaw-deg A      and A degrees off its true yaw, sign alternating (default 0)\n"
    "  --repeat N             align each accepted pair N more times, each from the last result\n"
    "  --neighbour-gap N      pairs at most N submap ids apart count as neighbours (default 3)\n"
    "  --rows                 print every constraint, not only the summary\n"
    "  --walls                also the wall match alone (pipeline/wall_map.h) of every overlapping "
    "revisit\n";

constexpr double kPi = 3.14159265358979323846;
constexpr double kGoldenAngleRad = 2.399963229728653;

double wrap_angle(double a) { return std::atan2(std::sin(a), std::cos(a)); }

// First-scan stamps per submap id from a run_slam --graph dump ('submap ID START_S END_S ...').
std::map<int64_t, double> read_submap_stamps(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw Error("cannot open graph dump " + path);
  std::map<int64_t, double> stamps;
  std::string line;
  while (std::getline(file, line)) {
    std::istringstream fields(line);
    std::string kind;
    int64_t id = 0;
    double start_s = 0.0;
    if (fields >> kind && kind == "submap" && fields >> id >> start_s) stamps[id] = start_s;
  }
  if (stamps.empty()) throw Error("graph dump " + path + " has no 'submap' lines");
  return stamps;
}

// The true pose at `stamp_s` (trajectory_evaluation's interpolation); throws outside the file.
Eigen::Isometry3d true_pose_at(const io::Trajectory& truth, double stamp_s,
                               const std::string& path) {
  io::StampedPose stamped;
  if (!tools::interpolate_pose(truth, stamp_s, &stamped)) {
    throw Error(path + " does not cover stamp " + std::to_string(stamp_s));
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = stamped.orientation.toRotationMatrix();
  pose.translation() = stamped.position_m;
  return pose;
}

double median(std::vector<double> values) {
  if (values.empty()) return NAN;
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

double mean(const std::vector<double>& values) {
  double sum = 0.0;
  for (double v : values) sum += v;
  return values.empty() ? NAN : sum / values.size();
}

struct PairError {
  int64_t from = 0, to = 0;
  double horizontal_m = 0.0, vertical_m = 0.0, yaw_deg = 0.0;
  // Signed error along the true relative translation (negative: the pair drawn closer), and that
  // translation's length: a systematic along-track error is a scale error of the trajectory.
  double along_m = 0.0, length_m = 0.0;
};

PairError pair_error(int64_t from, int64_t to, const backend::Pose4Dof& found,
                     const backend::Pose4Dof& expected) {
  PairError e;
  e.from = from;
  e.to = to;
  e.horizontal_m = std::hypot(found.x - expected.x, found.y - expected.y);
  e.vertical_m = found.z - expected.z;
  e.yaw_deg = wrap_angle(found.yaw - expected.yaw) * 180.0 / kPi;
  e.length_m = std::hypot(expected.x, expected.y);
  if (e.length_m > 1e-6)
    e.along_m =
        ((found.x - expected.x) * expected.x + (found.y - expected.y) * expected.y) / e.length_m;
  return e;
}

void print_group(const char* name, const std::vector<PairError>& errors) {
  std::vector<double> horizontal, vertical, yaw;
  int64_t over_half_metre = 0;
  double along_sum = 0.0, length_sum = 0.0;
  for (const PairError& e : errors) {
    along_sum += e.along_m;
    length_sum += e.length_m;
    horizontal.push_back(e.horizontal_m);
    vertical.push_back(std::abs(e.vertical_m));
    yaw.push_back(std::abs(e.yaw_deg));
    over_half_metre += e.horizontal_m > 0.5;
  }
  std::printf("%-11s %5zu %10.3f %10.3f %10.3f %10.2f %8lld %10.3f %10.2f\n", name, errors.size(),
              median(horizontal), mean(horizontal), median(vertical), median(yaw),
              static_cast<long long>(over_half_metre),
              errors.empty() ? NAN : along_sum / errors.size(),
              length_sum > 0.0 ? 100.0 * along_sum / length_sum : NAN);
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  const std::string map_path = args.text("--map", "");
  const std::string graph_path = args.text("--graph", "");
  const std::string truth_path = args.text("--truth", "");
  const std::string config_path = args.text("--config", "");
  const std::string device_text = args.text("--device", "auto");
  const double start_offset_m = args.number("--start-offset-m", 0.0);
  const double start_yaw_deg = args.number("--start-yaw-deg", 0.0);
  const int64_t neighbour_gap = args.integer("--neighbour-gap", 3);
  const int64_t repeat = args.integer("--repeat", 0);
  const bool rows = args.flag("--rows");
  const bool walls = args.flag("--walls");
  args.finish();
  if (map_path.empty() || graph_path.empty() || truth_path.empty())
    args.fail("--map, --graph and --truth are required");
  if (!(start_offset_m >= 0.0)) args.fail("--start-offset-m must be >= 0");
  if (repeat < 0) args.fail("--repeat must be >= 0");

  try {
    const Device device = select_device(parse_device_request(device_text));
    pipeline::SlamConfig config = pipeline::load_preset("arche_sim");
    config.device = device;
    if (!config_path.empty()) pipeline::load_slam_config(config_path, &config);
    pipeline::validate(config.registration);
    const io::MapFileContents contents = io::load_map_file(map_path);
    if (!contents.has_esdf) throw Error(map_path + " has no ESDF (registration needs it)");
    const std::map<int64_t, double> stamps = read_submap_stamps(graph_path);
    const io::Trajectory truth = io::read_tum_trajectory(truth_path);
    if (!truth.has_orientations) throw Error(truth_path + " has no orientations");
    std::vector<std::unique_ptr<TsdfMap>> maps = io::make_maps(contents, device);
    const Stream stream(device);

    std::vector<pipeline::RegistrationPartner> earlier;
    std::vector<PairError> neighbours, revisits, wall_matches;
    std::vector<std::unique_ptr<pipeline::WallMapCache>>
        wall_caches;  // one per submap, as the SLAM system keeps
    std::vector<std::unique_ptr<pipeline::SubmapRegistrationPoints>>
        kept_points;  // the same for their points
    pipeline::RegistrationCounts counts;
    std::map<int64_t, backend::Pose4Dof> true_pose;
    if (rows) std::printf("from -> to   horizontal_m  vertical_m  yaw_deg  along_m\n");
    for (size_t k = 0; k < contents.submaps.size(); ++k) {
      const int64_t id = contents.submaps[k].id;
      const auto stamp = stamps.find(id);
      if (stamp == stamps.end())
        throw Error("submap " + std::to_string(id) + " is not in " + graph_path);
      const backend::Pose4Dof truth_k =
          pipeline::pose_4dof_from_isometry(true_pose_at(truth, stamp->second, truth_path));
      true_pose[id] = truth_k;
      backend::Pose4Dof start = truth_k;
      const double direction = kGoldenAngleRad * static_cast<double>(k);
      start.x += start_offset_m * std::cos(direction);
      start.y += start_offset_m * std::sin(direction);
      start.yaw = wrap_angle(start.yaw + (k % 2 ? 1.0 : -1.0) * start_yaw_deg * kPi / 180.0);
      kept_points.push_back(
          pipeline::prepare_registration_points(*maps[k], config.registration, stream));
      const std::unique_ptr<pipeline::SubmapRegistrationPoints>& points = kept_points.back();
      wall_caches.push_back(std::make_unique<pipeline::WallMapCache>());
      pipeline::WallMapCache* const own_walls = wall_caches.back().get();
      const std::vector<pipeline::SubmapConstraint> constraints =
          pipeline::registration_constraints(id, *maps[k], *points, start, earlier,
                                             config.registration, stream, &counts, own_walls);
      if (walls) {
        for (const pipeline::RegistrationPartner* partner :
             pipeline::overlapping_partners(*maps[k], start, earlier, config.registration)) {
          if (id - partner->id < config.registration.revisits.min_id_gap) continue;
          pipeline::WallSearchConfig search;
          search.range_m = config.registration.revisits.wall_search_range_m;
          const pipeline::WallMatch match = pipeline::match_walls(
              own_walls->get(*maps[k], stream), partner->walls->get(*partner->map, stream),
              pipeline::relative_pose_4dof(partner->pose, start), search);
          const backend::Pose4Dof expected =
              pipeline::relative_pose_4dof(true_pose.at(partner->id), truth_k);
          const PairError e = pair_error(partner->id, id, match.T_fixed_moving, expected);
          wall_matches.push_back(e);
          if (rows) {
            std::printf("walls %4lld -> %-4lld %11.3f %8.2f score %.1f\n",
                        static_cast<long long>(e.from), static_cast<long long>(e.to),
                        e.horizontal_m, e.yaw_deg, match.score);
          }
        }
      }
      for (pipeline::SubmapConstraint c : constraints) {
        for (int64_t again = 0; again < repeat; ++again) {
          const pipeline::RegistrationPartner* partner = nullptr;
          for (const pipeline::RegistrationPartner& p : earlier) {
            if (p.id == c.from_submap) partner = &p;
          }
          pipeline::RegistrationCounts ignored;
          const std::vector<pipeline::SubmapConstraint> redo = pipeline::registration_constraints(
              id, *maps[k], *points, pipeline::compose(partner->pose, c.measurement), {*partner},
              config.registration, stream, &ignored);
          if (redo.empty()) break;
          c = redo.front();
        }
        const backend::Pose4Dof expected =
            pipeline::relative_pose_4dof(true_pose.at(c.from_submap), truth_k);
        const PairError e = pair_error(c.from_submap, c.to_submap, c.measurement, expected);
        (e.to - e.from <= neighbour_gap ? neighbours : revisits).push_back(e);
        if (rows) {
          std::printf("%4lld -> %-4lld %11.3f %11.3f %8.2f %8.3f\n", static_cast<long long>(e.from),
                      static_cast<long long>(e.to), e.horizontal_m, e.vertical_m, e.yaw_deg,
                      e.along_m);
        }
      }
      earlier.push_back(
          pipeline::RegistrationPartner{id, maps[k].get(), truth_k, own_walls, points.get()});
    }
    std::printf(
        "registration from %.2f m / %.1f deg off the truth (%s): %lld attempted, %lld accepted\n",
        start_offset_m, start_yaw_deg, describe_device(device).c_str(),
        static_cast<long long>(counts.attempted), static_cast<long long>(counts.accepted));
    std::printf("%-11s %5s %10s %10s %10s %10s %8s %10s %10s\n", "pairs", "n", "med_xy_m",
                "mean_xy_m", "med_z_m", "med_yaw_deg", ">0.5m", "along_m", "scale_%");
    print_group("neighbours", neighbours);
    print_group("revisits", revisits);
    std::vector<PairError> all = neighbours;
    all.insert(all.end(), revisits.begin(), revisits.end());
    print_group("all", all);
    if (walls) print_group("wall match", wall_matches);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "registration_accuracy: %s\n", error.what());
    return 1;
  }
  return 0;
}

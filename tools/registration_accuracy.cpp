// registration_accuracy: how close submap-to-submap registration lands to the true relative pose
// when it starts there (or a known distance away). It separates the registration's own bias
// from the graph's: on a flight whose odometry equals the truth (`simulate_flight --drift-scale
// 0`) a perfect registration would return the true relative pose for every pair.
//
// Input: a map saved by `run_slam --map` (submap voxels and ESDF), the same run's `--graph` dump
// (each submap's first-scan stamp) and the flight's true sensor poses (TUM). Each submap is
// placed at its true pose (gravity aligned) and registered to every earlier submap it overlaps,
// exactly as the SLAM system does (pipeline::registration_constraints: coarse-to-fine levels,
// symmetric solve, acceptance tests), with the registration settings of the arche preset and an
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
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cli/command_line.h"
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
#include "runner/slam_run.h"
#include "eval/submap_truth.h"
#include "eval/trajectory_evaluation.h"

using namespace covox;

namespace {

const char* kUsage =
    "usage: registration_accuracy --map FILE --graph FILE --truth FILE.tum [options]\n"
    "  --map FILE             map saved by run_slam --map (submaps with their ESDF)\n"
    "  --graph FILE           the same run's run_slam --graph dump (submap first-scan stamps)\n"
    "  --truth FILE.tum       true sensor poses (simulate_flight's truth.tum)\n"
    "  --config FILE.yaml     a configuration file over the arche preset (only registration "
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

struct Options {
  std::string map_path, graph_path, truth_path, config_path, device_text;
  double start_offset_m = 0.0;
  double start_yaw_deg = 0.0;
  int64_t neighbour_gap = 3;
  int64_t repeat = 0;
  bool rows = false;
  bool walls = false;
};

Options parse_options(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  Options o;
  o.map_path = args.text("--map", "");
  o.graph_path = args.text("--graph", "");
  o.truth_path = args.text("--truth", "");
  o.config_path = args.text("--config", "");
  o.device_text = args.text("--device", "auto");
  o.start_offset_m = args.number("--start-offset-m", 0.0, 0.0, 100.0);
  o.start_yaw_deg = args.number("--start-yaw-deg", 0.0, -180.0, 180.0);
  o.neighbour_gap = args.integer("--neighbour-gap", 3, 1, 1000000);
  o.repeat = args.integer("--repeat", 0, 0, 1000000);
  o.rows = args.flag("--rows");
  o.walls = args.flag("--walls");
  args.finish();
  if (o.map_path.empty() || o.graph_path.empty() || o.truth_path.empty())
    args.fail("--map, --graph and --truth are required");
  return o;
}

// What the evaluation reads: the registration settings, the saved submaps (on the device), the
// submaps' first-scan stamps and the true poses.
struct Inputs {
  pipeline::SlamConfig config;
  io::MapFileContents contents;
  std::map<int64_t, eval::SubmapSpan> spans;
  io::Trajectory truth;
  std::vector<std::unique_ptr<map::TsdfMap>> maps;
};

Inputs load_inputs(const Options& o, Device device) {
  Inputs in;
  in.config = pipeline::load_preset("arche");
  in.config.device = device;
  if (!o.config_path.empty()) pipeline::load_slam_config(o.config_path, &in.config);
  pipeline::validate(in.config.registration);
  in.contents = io::load_map_file(o.map_path);
  in.spans = eval::read_submap_spans(o.graph_path);
  in.truth = io::read_tum_trajectory(o.truth_path);
  if (!in.truth.has_orientations) throw Error(o.truth_path + " has no orientations");
  in.maps = io::make_maps(in.contents, device);
  // Version 2 map files store no ESDF: it is recomputed from the TSDF, as loading a map does.
  if (!in.contents.has_esdf) {
    for (auto& map : in.maps)
      integrators::EsdfIntegrator(in.config.esdf).update_all(*map, Stream(device));
  }
  return in;
}

// The submaps registered so far, with what the SLAM system keeps per submap (its wall map cache
// and registration points, which the partners point at), and the errors found.
struct Evaluation {
  std::vector<pipeline::RegistrationPartner> earlier;
  std::vector<PairError> neighbours, revisits, wall_matches;
  std::vector<std::unique_ptr<pipeline::WallMapCache>> wall_caches;
  std::vector<std::unique_ptr<pipeline::SubmapRegistrationPoints>> kept_points;
  pipeline::RegistrationCounts counts;
  std::map<int64_t, backend::Pose4Dof> true_pose;
};

// Where submap k's registration starts: its true pose, moved start_offset_m along a direction
// that turns by the golden angle per submap and turned by start_yaw_deg of alternating sign.
backend::Pose4Dof start_pose(const backend::Pose4Dof& truth_k, size_t k, const Options& o) {
  backend::Pose4Dof start = truth_k;
  const double direction = kGoldenAngleRad * static_cast<double>(k);
  start.x += o.start_offset_m * std::cos(direction);
  start.y += o.start_offset_m * std::sin(direction);
  start.yaw = wrap_angle(start.yaw + (k % 2 ? 1.0 : -1.0) * o.start_yaw_deg * kPi / 180.0);
  return start;
}

// One submap being registered: its id, index, map, points, wall cache and poses.
struct NewSubmap {
  int64_t id;
  size_t k;
  map::TsdfMap* map;
  const pipeline::SubmapRegistrationPoints* points;
  pipeline::WallMapCache* walls;
  backend::Pose4Dof truth;
  backend::Pose4Dof start;
};

// The wall match alone against every overlapping revisit partner, started where the
// registration starts.
void evaluate_wall_matches(const NewSubmap& s, const Options& o, const Inputs& in,
                           const Stream& stream, Evaluation& ev) {
  const pipeline::SubmapRegistrationConfig& registration = in.config.registration;
  for (const pipeline::RegistrationPartner* partner :
       pipeline::overlapping_partners(*s.map, s.start, ev.earlier, registration)) {
    if (s.id - partner->id < registration.revisits.min_id_gap) continue;
    pipeline::WallSearchConfig search;
    search.range_m = registration.revisits.wall_search_range_m;
    const pipeline::WallMatch match = pipeline::match_walls(
        s.walls->get(*s.map, stream), partner->walls->get(*partner->map, stream),
        pipeline::relative_pose_4dof(partner->pose, s.start), search);
    const backend::Pose4Dof expected =
        pipeline::relative_pose_4dof(ev.true_pose.at(partner->id), s.truth);
    const PairError e = pair_error(partner->id, s.id, match.T_fixed_moving, expected);
    ev.wall_matches.push_back(e);
    if (o.rows) {
      std::printf("walls %4lld -> %-4lld %11.3f %8.2f score %.1f\n", static_cast<long long>(e.from),
                  static_cast<long long>(e.to), e.horizontal_m, e.yaw_deg, match.score);
    }
  }
}

// Registers the accepted constraint `c` again `repeat` times, each from the last result (its
// partner's pose composed with the measurement); stops early when a re-registration is refused.
pipeline::SubmapConstraint realign(pipeline::SubmapConstraint c, const NewSubmap& s,
                                   const Options& o, const Inputs& in, const Stream& stream,
                                   const Evaluation& ev) {
  for (int64_t again = 0; again < o.repeat; ++again) {
    const pipeline::RegistrationPartner* partner = nullptr;
    for (const pipeline::RegistrationPartner& p : ev.earlier) {
      if (p.id == c.from_submap) partner = &p;
    }
    pipeline::RegistrationCounts ignored;
    const std::vector<pipeline::SubmapConstraint> redo = pipeline::registration_constraints(
        s.id, *s.map, *s.points, pipeline::compose(partner->pose, c.measurement), {*partner},
        in.config.registration, stream, &ignored);
    if (redo.empty()) break;
    c = redo.front();
  }
  return c;
}

// Registers submap k to the earlier ones from its start pose, records each accepted
// constraint's error, and adds the submap to the partners at its true pose.
void evaluate_submap(size_t k, const Options& o, const Inputs& in, const Stream& stream,
                     Evaluation& ev) {
  const int64_t id = in.contents.submaps[k].id;
  const auto span = in.spans.find(id);
  if (span == in.spans.end())
    throw Error("submap " + std::to_string(id) + " is not in " + o.graph_path);
  const backend::Pose4Dof truth_k = pipeline::pose_4dof_from_isometry(
      eval::true_pose_at(in.truth, span->second.start_s, o.truth_path));
  ev.true_pose[id] = truth_k;
  const backend::Pose4Dof start = start_pose(truth_k, k, o);
  ev.kept_points.push_back(
      pipeline::prepare_registration_points(*in.maps[k], in.config.registration, stream));
  ev.wall_caches.push_back(std::make_unique<pipeline::WallMapCache>());
  const NewSubmap s{
      id,      k,    in.maps[k].get(), ev.kept_points.back().get(), ev.wall_caches.back().get(),
      truth_k, start};
  const std::vector<pipeline::SubmapConstraint> constraints =
      pipeline::registration_constraints(id, *s.map, *s.points, start, ev.earlier,
                                         in.config.registration, stream, &ev.counts, s.walls);
  if (o.walls) evaluate_wall_matches(s, o, in, stream, ev);
  for (const pipeline::SubmapConstraint& accepted : constraints) {
    const pipeline::SubmapConstraint c = realign(accepted, s, o, in, stream, ev);
    const backend::Pose4Dof expected =
        pipeline::relative_pose_4dof(ev.true_pose.at(c.from_submap), truth_k);
    const PairError e = pair_error(c.from_submap, c.to_submap, c.measurement, expected);
    (e.to - e.from <= o.neighbour_gap ? ev.neighbours : ev.revisits).push_back(e);
    if (o.rows) {
      std::printf("%4lld -> %-4lld %11.3f %11.3f %8.2f %8.3f\n", static_cast<long long>(e.from),
                  static_cast<long long>(e.to), e.horizontal_m, e.vertical_m, e.yaw_deg, e.along_m);
    }
  }
  pipeline::RegistrationPartner partner;
  partner.id = id;
  partner.map = s.map;
  partner.pose = truth_k;
  partner.walls = s.walls;
  partner.points = s.points;
  ev.earlier.push_back(partner);
}

void print_summary(const Options& o, Device device, const Evaluation& ev) {
  std::printf(
      "registration from %.2f m / %.1f deg off the truth (%s): %lld attempted, %lld accepted\n",
      o.start_offset_m, o.start_yaw_deg, describe_device(device).c_str(),
      static_cast<long long>(ev.counts.attempted), static_cast<long long>(ev.counts.accepted));
  std::printf("%-11s %5s %10s %10s %10s %10s %8s %10s %10s\n", "pairs", "n", "med_xy_m",
              "mean_xy_m", "med_z_m", "med_yaw_deg", ">0.5m", "along_m", "scale_%");
  print_group("neighbours", ev.neighbours);
  print_group("revisits", ev.revisits);
  std::vector<PairError> all = ev.neighbours;
  all.insert(all.end(), ev.revisits.begin(), ev.revisits.end());
  print_group("all", all);
  if (o.walls) print_group("wall match", ev.wall_matches);
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse_options(argc, argv);
  try {
    const Device device = select_device(parse_device_request(o.device_text));
    const Inputs in = load_inputs(o, device);
    const Stream stream(device);
    Evaluation ev;
    if (o.rows) std::printf("from -> to   horizontal_m  vertical_m  yaw_deg  along_m\n");
    for (size_t k = 0; k < in.contents.submaps.size(); ++k) evaluate_submap(k, o, in, stream, ev);
    print_summary(o, device, ev);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "registration_accuracy: %s\n", error.what());
    return 1;
  }
  return 0;
}

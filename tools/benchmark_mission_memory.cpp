// benchmark_mission_memory: a simulated mission mapped in process under the memory budgets of a
// configuration file (config/jetson.yaml by default), with the whole process's memory sampled
// along it - the device memory in use (the GPU's, total minus free) plus the host's resident set
// (VmRSS). It checks three limits and writes the figures as a benchmark report
// (docs/benchmarks/mission_jetson.json) and the timeline as a plot:
//   * ATE RMSE of the corrected trajectory against the truth <= --max-ate-m,
//   * device memory in use + host RSS <= --max-process-mb at every sample,
//   * host RSS growth once the budgets are reached <= --max-rss-growth-mb-per-s: the
//     least-squares slope of host RSS against mission time over the samples from the first one at
//     which the store keeps a submap in the spill file (so the device budget has compacted
//     submaps and the host budget has moved compact ones to disk) to the last one before the
//     final flush.
// The slope of the lowest host RSS of each window (--window-s) is reported beside it: the samples
// within a window swing with the partners a registration has brought back, the floor is what
// stays. On the CPU backend the voxel pools are host memory: nothing is counted as device memory,
// the whole process is its host RSS, and the slope of host RSS less the resident submaps' bytes
// (the device budget's share) is reported too.
//
//   build/benchmark_mission_memory --device cuda --columns 1024 --duration-s 1800 --drift-percent 1
//
// Exit status: 0 when every limit is met, 3 when one is missed (after writing the report), 1 on
// an error.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

#include "benchmark/benchmark_report.h"
#include "cli/command_line.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "eval/png_plot.h"
#include "eval/trajectory_evaluation.h"
#include "runner/sim_scan_source.h"
#include "runner/slam_run.h"
#include "sim/sim_mission.h"

namespace {

using namespace covox;

constexpr double kBytesPerMb = 1024.0 * 1024.0;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const char kUsage[] =
    "usage: benchmark_mission_memory [options] [simulator options]\n"
    "  --config FILE.yaml              configuration applied over the arche preset (default\n"
    "                                  config/jetson.yaml)\n"
    "  --device auto|cuda|cpu          (default auto)\n"
    "  --sample-interval-s S           a memory sample every S s of mission time (default 2)\n"
    "  --window-s S                    report and floor windows of S s of mission time (default "
    "60)\n"
    "  --max-ate-m M                   limit on the ATE RMSE (default 0.5)\n"
    "  --max-process-mb M              limit on device memory in use + host RSS (default 4096)\n"
    "  --max-rss-growth-mb-per-s G     limit on host RSS growth once the budgets are reached\n"
    "                                  (default 0.05)\n"
    "  --case NAME                     the report's case (default: the flight, e.g. "
    "1800s-1024col)\n"
    "  --json FILE                     report (default docs/benchmarks/mission_jetson.json)\n"
    "  --timeline-plot FILE.png        plot (default docs/images/mission_jetson.png)\n"
    "  --quiet                         no progress bar\n"
    "simulator (the mission's flight; e.g. --columns 1024 --duration-s 1800 --drift-percent 1):\n";

struct Settings {
  sim::SimulationOptions simulation;
  std::string config_path, device_text, case_name, json_path, plot_path;
  double sample_interval_s = 2.0;
  double window_s = 60.0;
  double max_ate_m = 0.5;
  double max_process_mb = 4096.0;
  double max_growth_mb_per_s = 0.05;
  bool quiet = false;
};

Settings read_settings(tools::CommandLine& args) {
  Settings s;
  s.config_path = args.text("--config", "config/jetson.yaml");
  s.device_text = args.text("--device", "auto");
  s.sample_interval_s = args.number("--sample-interval-s", s.sample_interval_s, 0.1, 3600.0);
  s.window_s = args.number("--window-s", s.window_s, 1.0, 86400.0);
  s.max_ate_m = args.number("--max-ate-m", s.max_ate_m, 0.0, 1e6);
  s.max_process_mb = args.number("--max-process-mb", s.max_process_mb, 0.0, 1e9);
  s.max_growth_mb_per_s = args.number("--max-rss-growth-mb-per-s", s.max_growth_mb_per_s, 0.0, 1e6);
  s.case_name = args.text("--case", "");
  s.json_path = args.output_file("--json", "docs/benchmarks/mission_jetson.json");
  s.plot_path = args.output_file("--timeline-plot", "docs/images/mission_jetson.png");
  s.quiet = args.flag("--quiet");
  s.simulation = sim::read_simulation_options(args);
  args.finish();
  if (s.window_s < s.sample_interval_s)
    args.fail("--window-s must be at least --sample-interval-s");
  return s;
}

// One sample's whole process: device memory in use (none on the CPU) plus host RSS.
double process_mb(const tools::TimelineSample& t) {
  return t.host_rss_mb + (std::isfinite(t.device_used_mb) ? t.device_used_mb : 0.0);
}

// Least-squares slope of y against x; NaN for fewer than two distinct x.
double slope(const std::vector<eval::PlotPoint>& points) {
  if (points.size() < 2) return kNaN;
  double mean_x = 0.0, mean_y = 0.0;
  for (const eval::PlotPoint& p : points) {
    mean_x += p.x;
    mean_y += p.y;
  }
  mean_x /= points.size();
  mean_y /= points.size();
  double sxy = 0.0, sxx = 0.0;
  for (const eval::PlotPoint& p : points) {
    sxy += (p.x - mean_x) * (p.y - mean_y);
    sxx += (p.x - mean_x) * (p.x - mean_x);
  }
  return sxx > 0.0 ? sxy / sxx : kNaN;
}

// The figures of a mission's memory, from its timeline.
struct MemoryFigures {
  double process_max_mb = 0.0;      // device memory in use + host RSS, the most of any sample
  double device_max_mb = kNaN;      // device memory in use, the most of any sample (GPU only)
  double host_peak_mb = 0.0;        // VmHWM at the end
  double budgets_reached_s = kNaN;  // mission time of the first sample with a submap on disk
  double rss_at_budgets_mb = kNaN;
  double rss_growth_mb_per_s = kNaN;        // slope over the samples from budgets_reached_s
  double rss_floor_growth_mb_per_s = kNaN;  // slope of each window's lowest RSS from there
  // The slope of host RSS less the resident submaps' bytes from there: on the CPU backend their
  // voxel pools (the device budget's memory) are host memory and swing with the partners a
  // registration brings back; what is left is the host's own.
  double rss_less_resident_growth_mb_per_s = kNaN;
  size_t samples_after = 0;
};

// Each window's lowest host RSS, at the window's middle, over the samples in `after`; a window
// with fewer than `min_samples` (the first and the last, cut short) is left out.
std::vector<eval::PlotPoint> window_floors(const std::vector<tools::TimelineSample>& after,
                                           double window_s, size_t min_samples) {
  std::vector<eval::PlotPoint> floors;
  std::vector<size_t> counts;
  for (const tools::TimelineSample& t : after) {
    const double middle = (std::floor(t.mission_s / window_s) + 0.5) * window_s;
    if (floors.empty() || floors.back().x != middle) {
      floors.push_back(eval::PlotPoint{middle, t.host_rss_mb});
      counts.push_back(0);
    }
    floors.back().y = std::min(floors.back().y, t.host_rss_mb);
    ++counts.back();
  }
  std::vector<eval::PlotPoint> full;
  for (size_t i = 0; i < floors.size(); ++i)
    if (counts[i] >= min_samples) full.push_back(floors[i]);
  return full;
}

MemoryFigures memory_figures(const std::vector<tools::TimelineSample>& timeline,
                             const Settings& s) {
  MemoryFigures f;
  std::vector<tools::TimelineSample> after;
  for (const tools::TimelineSample& t : timeline) {
    f.process_max_mb = std::max(f.process_max_mb, process_mb(t));
    if (std::isfinite(t.device_used_mb))
      f.device_max_mb = std::isfinite(f.device_max_mb) ? std::max(f.device_max_mb, t.device_used_mb)
                                                       : t.device_used_mb;
    f.host_peak_mb = std::max(f.host_peak_mb, t.host_peak_rss_mb);
    if (t.end) continue;  // the flush and the final solve, not the mission
    if (!std::isfinite(f.budgets_reached_s) && t.memory.submaps_on_disk > 0) {
      f.budgets_reached_s = t.mission_s;
      f.rss_at_budgets_mb = t.host_rss_mb;
    }
    if (std::isfinite(f.budgets_reached_s)) after.push_back(t);
  }
  std::vector<eval::PlotPoint> rss, less_resident;
  for (const tools::TimelineSample& t : after) {
    rss.push_back(eval::PlotPoint{t.mission_s, t.host_rss_mb});
    less_resident.push_back(
        eval::PlotPoint{t.mission_s, t.host_rss_mb - t.memory.resident_bytes / kBytesPerMb});
  }
  f.samples_after = after.size();
  f.rss_growth_mb_per_s = slope(rss);
  f.rss_less_resident_growth_mb_per_s = slope(less_resident);
  const size_t full_window = static_cast<size_t>(s.window_s / s.sample_interval_s);
  f.rss_floor_growth_mb_per_s =
      slope(window_floors(after, s.window_s, std::max<size_t>(2, full_window / 2)));
  return f;
}

struct Verdict {
  bool ate_met = false, process_met = false, growth_met = false;
  bool all() const { return ate_met && process_met && growth_met; }
};

Verdict check(const Settings& s, const MemoryFigures& f, double ate_m) {
  Verdict v;
  v.ate_met = std::isfinite(ate_m) && ate_m <= s.max_ate_m;
  v.process_met = f.process_max_mb <= s.max_process_mb;
  // Budgets never reached: no growth to judge, which the report says (NaN) and counts as missed.
  v.growth_met =
      std::isfinite(f.rss_growth_mb_per_s) && f.rss_growth_mb_per_s <= s.max_growth_mb_per_s;
  return v;
}

// Per window of the timeline: the most the whole process and the device took, the lowest and the
// most host RSS, and where the finished submaps were at its end.
void add_window_rows(tools::BenchmarkReport* report,
                     const std::vector<tools::TimelineSample>& timeline, double window_s) {
  size_t i = 0;
  while (i < timeline.size()) {
    const double window = std::floor(timeline[i].mission_s / window_s);
    double process = 0.0, device = kNaN, rss_min = timeline[i].host_rss_mb, rss_max = 0.0;
    size_t last = i;
    for (; last < timeline.size() && !timeline[last].end &&
           std::floor(timeline[last].mission_s / window_s) == window;
         ++last) {
      const tools::TimelineSample& t = timeline[last];
      process = std::max(process, process_mb(t));
      if (std::isfinite(t.device_used_mb))
        device = std::isfinite(device) ? std::max(device, t.device_used_mb) : t.device_used_mb;
      rss_min = std::min(rss_min, t.host_rss_mb);
      rss_max = std::max(rss_max, t.host_rss_mb);
    }
    if (last == i) ++last;  // the final sample: a window of its own
    const tools::TimelineSample& end = timeline[last - 1];
    char name[40];
    std::snprintf(name, sizeof(name), "t=%04.0fs%s", end.mission_s, end.end ? " end" : "");
    report->add(name, "device memory used + host RSS max", std::max(process, process_mb(end)),
                "MB");
    if (std::isfinite(device)) report->add(name, "device memory used max", device, "MB");
    report->add(name, "host RSS min", std::min(rss_min, end.host_rss_mb), "MB");
    report->add(name, "host RSS max", std::max(rss_max, end.host_rss_mb), "MB");
    report->add(name, "submaps", static_cast<double>(end.submaps), "");
    report->add(name, "submaps resident", static_cast<double>(end.memory.submaps_resident), "");
    report->add(name, "submaps compact", static_cast<double>(end.memory.submaps_compact), "");
    report->add(name, "submaps on disk", static_cast<double>(end.memory.submaps_on_disk), "");
    i = last;
  }
}

void add_summary_rows(tools::BenchmarkReport* report, const std::string& name, const Settings& s,
                      const tools::SlamRunResult& result,
                      const tools::SlamRunEvaluation& evaluation, const MemoryFigures& f,
                      const Verdict& v) {
  const pipeline::SubmapStoreCounters& m = result.counters.memory;
  report->add(name, "scans", static_cast<double>(result.scans_given), "");
  report->add(name, "wall time", result.wall_s, "s");
  report->add(name, "real-time factor", result.real_time_factor(), "x");
  report->add(name, "submaps", static_cast<double>(result.submaps.size()), "");
  report->add(name, "ATE RMSE odometry", evaluation.odometry.absolute_position_m.rmse, "m");
  report->add(name, "ATE RMSE covoxslam", evaluation.corrected.absolute_position_m.rmse, "m");
  report->add(name, "device memory used + host RSS max", f.process_max_mb, "MB");
  report->add(name, "device memory used max", f.device_max_mb, "MB");
  report->add(name, "host peak RSS", f.host_peak_mb, "MB");
  report->add(name, "budgets reached at", f.budgets_reached_s, "s");
  report->add(name, "host RSS at budgets reached", f.rss_at_budgets_mb, "MB");
  report->add(name, "host RSS growth after budgets reached", f.rss_growth_mb_per_s, "MB/s");
  report->add(name, "host RSS floor growth after budgets reached", f.rss_floor_growth_mb_per_s,
              "MB/s");
  report->add(name, "host RSS less resident submaps growth after budgets reached",
              f.rss_less_resident_growth_mb_per_s, "MB/s");
  report->add(name, "samples after budgets reached", static_cast<double>(f.samples_after), "");
  report->add(name, "submaps resident at the end", static_cast<double>(m.submaps_resident), "");
  report->add(name, "submaps compact at the end", static_cast<double>(m.submaps_compact), "");
  report->add(name, "submaps on disk at the end", static_cast<double>(m.submaps_on_disk), "");
  report->add(name, "peak resident submaps", m.peak_resident_bytes / kBytesPerMb, "MB");
  report->add(name, "submap restores", static_cast<double>(m.restores), "");
  report->add(name, "submap spills", static_cast<double>(m.spills), "");
  report->add(name, "submap spill failures", static_cast<double>(m.spill_failures), "");
  report->add(name, "limit ATE RMSE", s.max_ate_m, "m");
  report->add(name, "limit device memory used + host RSS", s.max_process_mb, "MB");
  report->add(name, "limit host RSS growth", s.max_growth_mb_per_s, "MB/s");
  report->add(name, "ATE limit met", v.ate_met ? 1.0 : 0.0, "");
  report->add(name, "memory limit met", v.process_met ? 1.0 : 0.0, "");
  report->add(name, "growth limit met", v.growth_met ? 1.0 : 0.0, "");
}

eval::PlotSeries series(const std::string& label, size_t colour) {
  eval::PlotSeries line;
  line.label = label;
  line.colour = eval::series_colour(colour);
  return line;
}

// Memory of the whole process above where the finished submaps were, against mission time, with
// the limit and the budgets as level lines.
void write_plot(const std::string& path, const std::vector<tools::TimelineSample>& timeline,
                const Settings& s, const pipeline::MemoryBudgetConfig& budgets) {
  std::vector<eval::PlotPanel> panels(2);
  panels[0].title = "MEMORY (MB) OVER MISSION TIME (S): DEVICE USED + HOST RSS, LIMIT";
  eval::PlotSeries process = series("device used + host RSS", 0), rss = series("host RSS", 1),
                   device = series("device used", 2), limit = series("limit", 3);
  panels[1].title = "FINISHED SUBMAPS (MB): RESIDENT, COMPACT IN HOST MEMORY, BUDGETS";
  eval::PlotSeries resident = series("resident", 0), compact = series("compact", 1),
                   device_budget = series("device budget", 2),
                   host_budget = series("host budget", 3);
  for (const tools::TimelineSample& t : timeline) {
    if (t.end) continue;
    process.points.push_back({t.mission_s, process_mb(t)});
    rss.points.push_back({t.mission_s, t.host_rss_mb});
    device.points.push_back({t.mission_s, t.device_used_mb});
    limit.points.push_back({t.mission_s, s.max_process_mb});
    resident.points.push_back({t.mission_s, t.memory.resident_bytes / kBytesPerMb});
    compact.points.push_back({t.mission_s, t.memory.compact_bytes / kBytesPerMb});
    device_budget.points.push_back({t.mission_s, budgets.device_budget_mb});
    host_budget.points.push_back({t.mission_s, budgets.host_budget_mb});
  }
  panels[0].series = {process, rss};
  if (!timeline.empty() && std::isfinite(timeline.front().device_used_mb))
    panels[0].series.push_back(device);
  panels[0].series.push_back(limit);
  panels[1].series = {resident, compact, device_budget, host_budget};
  eval::write_png(path, eval::render_stacked_panels(panels));
  std::printf("timeline plot -> %s\n", path.c_str());
}

void print_figures(const Settings& s, const tools::SlamRunEvaluation& evaluation,
                   const MemoryFigures& f, const Verdict& v, bool cpu) {
  auto mark = [](bool met) { return met ? "met" : "MISSED"; };
  std::printf("\nATE RMSE: %.3f m (odometry %.3f m), limit %.3f m: %s\n",
              evaluation.corrected.absolute_position_m.rmse,
              evaluation.odometry.absolute_position_m.rmse, s.max_ate_m, mark(v.ate_met));
  std::printf(
      "device memory used + host RSS: at most %.1f MB over the samples%s, limit %.1f MB: %s\n",
      f.process_max_mb, cpu ? " (CPU backend: host RSS only)" : "", s.max_process_mb,
      mark(v.process_met));
  std::printf(
      "budgets reached at %.0f s (host RSS %.1f MB); host RSS growth after it %.4f MB/s "
      "over %zu samples (window floors %.4f MB/s, less resident submaps %.4f MB/s), limit "
      "%.4f MB/s: %s\n",
      f.budgets_reached_s, f.rss_at_budgets_mb, f.rss_growth_mb_per_s, f.samples_after,
      f.rss_floor_growth_mb_per_s, f.rss_less_resident_growth_mb_per_s, s.max_growth_mb_per_s,
      mark(v.growth_met));
}

int run(Settings& s, int argc, char** argv) {
  const Device device = select_device(parse_device_request(s.device_text));
  pipeline::SlamConfig config = pipeline::load_preset("arche");
  pipeline::load_slam_config(s.config_path, &config);
  config.device = device;
  pipeline::validate(config);
  tools::SimScanSource source(s.simulation, /*min_range_m=*/0.5);
  if (s.case_name.empty()) {
    char name[64];
    std::snprintf(name, sizeof(name), "%.0fs-%dcol",
                  s.simulation.flight.path_length_m / s.simulation.flight.speed_m_per_s,
                  s.simulation.lidar.columns);
    s.case_name = name;
  }
  std::printf(
      "device: %s\ninput: %s\nconfig: arche + %s (device budget %.0f MB, host budget "
      "%.0f MB, device cache %.0f MB)\n",
      describe_device(device).c_str(), source.describe().c_str(), s.config_path.c_str(),
      config.memory.device_budget_mb, config.memory.host_budget_mb, config.memory.device_cache_mb);
  std::fflush(stdout);
  tools::SlamRunOptions options;
  options.progress_bar = !s.quiet;
  options.timeline_interval_s = s.sample_interval_s;
  const tools::SlamRunResult result = tools::run_slam_system(source, config, options);
  const tools::SlamRunEvaluation evaluation = tools::evaluate_slam_run(
      source, result, eval::AlignmentMode::kTranslationYaw, /*max_time_gap_s=*/0.1);
  const MemoryFigures figures = memory_figures(result.timeline, s);
  const double ate_m = evaluation.available ? evaluation.corrected.absolute_position_m.rmse : kNaN;
  const Verdict verdict = check(s, figures, ate_m);

  tools::BenchmarkReport report("mission_jetson", describe_device(device), argc, argv);
  add_summary_rows(&report, s.case_name, s, result, evaluation, figures, verdict);
  add_window_rows(&report, result.timeline, s.window_s);
  report.write_json(s.json_path);
  std::printf("real time: %.1f s of mission in %.1f s (%.2f x)\nreport -> %s\n",
              result.input_duration_s, result.wall_s, result.real_time_factor(),
              s.json_path.c_str());
  write_plot(s.plot_path, result.timeline, s, config.memory);
  print_figures(s, evaluation, figures, verdict, device == Device::kCpu);
  return verdict.all() ? 0 : 3;
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, std::string(kUsage) + sim::kSimulationUsage);
  Settings settings = read_settings(args);
  try {
    return run(settings, argc, argv);
  } catch (const Error& error) {
    std::cerr << "\nbenchmark_mission_memory: " << error.what() << std::endl;
    return 1;
  }
}

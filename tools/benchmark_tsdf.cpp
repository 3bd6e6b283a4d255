// TSDF integration time per frame on real data, GPU and CPU twin. Prints a table and writes
// docs/benchmarks/tsdf.json.
//
//   benchmark_tsdf [--data DIR] [--device all|cuda|cpu] [--integrations 100]
//                  [--output docs/benchmarks/tsdf.json] [--skip-rgbd] [--skip-lidar] [--case TEXT]
//
// --case runs only the cases whose name contains TEXT (for example "2 cm colour carving"), so
// that a kernel profiler sees one case's frames from the start.
//
// Each case maps its frames with a pipeline::Mapper configured from a preset of config/ and the
// case's own sizes. Cases: Ouster OS1-64 (newer_06) at 0.1 and 0.2 m voxels, truncation 3 voxels,
// 16 m rays (the `arche` preset, voxgraph's ARCHE setting); KITTI HDL-64 at 0.2 m with 50 m rays;
// 7-Scenes at 5 cm and 2 cm with colour (the `rgbd` preset's weighting), frames 0-69 (what nvblox
// was timed on).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "benchmark/benchmark_datasets.h"
#include "benchmark/benchmark_report.h"
#include "benchmark/benchmark_run.h"
#include "cli/command_line.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/pipeline/mapper.h"

namespace covox {
namespace {

struct Options {
  std::string data;
  std::string device = "all";
  int integrations = 100;
  std::string output;
  bool skip_rgbd = false;
  bool skip_lidar = false;
  std::string only_case;  // run only the cases whose name contains this (all when empty)
  bool runs(const std::string& name) const {
    return only_case.empty() || name.find(only_case) != std::string::npos;
  }
};

Options parse(int argc, char** argv) {
  tools::CommandLine args(
      argc, argv,
      "usage: benchmark_tsdf [--data DIR] [--device all|cuda|cpu] [--integrations N]\n"
      "       [--output docs/benchmarks/tsdf.json] [--skip-rgbd] [--skip-lidar]\n"
      "       [--case TEXT]");
  Options options;
  options.data = args.text("--data", io::data_directory());
  options.device = args.text("--device", options.device);
  options.integrations =
      static_cast<int>(args.positive_integer("--integrations", options.integrations));
  options.output = args.output_file("--output", "");
  options.skip_rgbd = args.flag("--skip-rgbd");
  options.skip_lidar = args.flag("--skip-lidar");
  options.only_case = args.text("--case", "");
  args.finish();
  return options;
}

struct Timing {
  double median_ms = 0.0;
  double updates_per_s = 0.0;
  int64_t blocks = 0;
  double rays_per_frame = 0.0;     // after merging points per voxel
  double updates_per_frame = 0.0;  // voxel updates before the segmented reduce
};

// Integrates frames round-robin into the mapper's map `integrations` times; the first pass over
// the frames is a warm-up (allocation of blocks and scratch), neither timed nor profiled.
template <class IntegrateFrame>
Timing time_integrations(const pipeline::Mapper& mapper, size_t frame_count, int integrations,
                         IntegrateFrame&& integrate_frame) {
  const Stream& stream = mapper.stream();
  for (size_t f = 0; f < frame_count; ++f) integrate_frame(f);
  stream.synchronize();
  // The stage profile (COVOX_PROFILE_STAGES) of the timed frames only: the warm-up's first frame
  // allocates and loads the kernels (milliseconds), which would swamp the stages' means.
  StageProfiler::reset();
  std::vector<double> times;
  int64_t updates = 0;
  int64_t rays = 0;
  double total_ms = 0.0;
  for (int i = 0; i < integrations; ++i) {
    integrators::IntegrationStats stats;
    const double ms = tools::stream_milliseconds(
        stream, [&] { stats = integrate_frame(static_cast<size_t>(i) % frame_count); });
    times.push_back(ms);
    total_ms += ms;
    updates += stats.voxel_updates;
    rays += stats.rays_cast;
  }
  return Timing{tools::median_of(times), updates / (total_ms * 1e-3), mapper.map().block_count(),
                static_cast<double>(rays) / integrations,
                static_cast<double>(updates) / integrations};
}

void add_rows(tools::BenchmarkReport* report, const std::string& name, const Timing& t) {
  tools::print_stage_profile(name);
  report->add(name, "median integration time", t.median_ms, "ms/frame");
  report->add(name, "voxel updates per second", t.updates_per_s / 1e6, "M/s");
  report->add(name, "allocated blocks", static_cast<double>(t.blocks), "blocks");
  report->add(name, "rays cast per frame (mean)", t.rays_per_frame, "rays");
  report->add(name, "voxel updates per frame (mean)", t.updates_per_frame, "updates");
}

// A drone's motion over one 0.1 s sweep: 2 m/s forward while turning at 30 deg/s.
integrators::SweepMotion drone_sweep() {
  Eigen::Isometry3d end = Eigen::Isometry3d::Identity();
  end.translation() = Eigen::Vector3d(0.2, 0.0, 0.0);
  end.linear() = Eigen::AngleAxisd(3.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return integrators::make_sweep_motion(Eigen::Isometry3d::Identity(),
                                        Eigen::Isometry3d::Identity(), end, 0.0, 0.1);
}

// `sweep`: the scans' points de-skewed by their times with this motion (stage 0).
void benchmark_lidar(Device device, const Options& options, const std::string& label,
                     const tools::DeviceScans& scans, float voxel_size, float max_ray_m,
                     integrators::TsdfIntegrationMethod method, tools::BenchmarkReport* report,
                     const integrators::SweepMotion* sweep = nullptr) {
  const std::string name = std::string(to_string(device)) + " " + label + ", " + to_string(method);
  if (!options.runs(name)) return;
  pipeline::MapperConfig config = pipeline::load_mapper_config({"arche"});
  config.device = device;
  config.map.voxel_size_m = voxel_size;
  config.tsdf.truncation_distance_m = 3.0f * voxel_size;
  config.tsdf.max_ray_length_m = max_ray_m;
  config.tsdf.method = method;
  pipeline::Mapper mapper(config);
  const Timing timing =
      time_integrations(mapper, scans.size(), options.integrations, [&](size_t f) {
        return mapper.integrate(scans.view(f, sweep), Eigen::Isometry3d::Identity());
      });
  add_rows(report, name, timing);
}

// nvblox was timed on frames 0-69 with depth only; we fuse colour as well, and raycast every
// pixel with free-space carving (voxblox semantics), `carving` off keeps only the band.
void benchmark_rgbd(Device device, const Options& options, const tools::DeviceRgbdFrames& frames,
                    float voxel_size, bool carving, tools::BenchmarkReport* report) {
  const std::string name = std::string(to_string(device)) + " 7-Scenes " +
                           std::to_string(int(voxel_size * 100 + 0.5)) + " cm colour" +
                           (carving ? " carving" : " band only");
  if (!options.runs(name)) return;
  pipeline::MapperConfig config = pipeline::load_mapper_config({"rgbd"});
  config.device = device;
  config.map.voxel_size_m = voxel_size;
  config.map.voxels_per_side = 8;
  config.tsdf.truncation_distance_m = 4.0f * voxel_size;  // nvblox's default truncation
  config.tsdf.max_ray_length_m = 5.0f;
  config.tsdf.voxel_carving_enabled = carving;
  pipeline::Mapper mapper(config);
  const Timing timing = time_integrations(
      mapper, frames.size(), options.integrations,
      [&](size_t f) { return mapper.integrate_depth(frames.view(f), frames.T_world_camera[f]); });
  add_rows(report, name, timing);
}

}  // namespace
}  // namespace covox

int main(int argc, char** argv) {
  using namespace covox;
  const Options options = parse(argc, argv);
  return tools::run_benchmark("benchmark_tsdf", [&] {
    const std::vector<Device> devices = tools::benchmark_devices(options.device);
    tools::BenchmarkReport report("tsdf", tools::describe_devices(devices), argc, argv);
    for (Device device : devices) {
      std::cout << "TSDF on " << describe_device(device) << "..." << std::endl;
      if (!options.skip_lidar) {
        const tools::DeviceScans ouster = tools::load_ouster_scans(options.data, device);
        const tools::DeviceScans kitti = tools::load_kitti_scans(options.data, device);
        const auto merged = integrators::TsdfIntegrationMethod::kMerged,
                   simple = integrators::TsdfIntegrationMethod::kSimple;
        benchmark_lidar(device, options, "OS1-64 0.2 m, 16 m rays", ouster, 0.2f, 16.0f, merged,
                        &report);
        benchmark_lidar(device, options, "OS1-64 0.2 m, 16 m rays", ouster, 0.2f, 16.0f, simple,
                        &report);
        benchmark_lidar(device, options, "OS1-64 0.1 m, 16 m rays", ouster, 0.1f, 16.0f, merged,
                        &report);
        // The cost of de-skewing: the same raw scans with and without their points' times.
        const tools::DeviceScans raw = tools::load_ouster_timed_scans(options.data, device);
        const integrators::SweepMotion sweep = drone_sweep();
        benchmark_lidar(device, options, "OS1-64 raw 0.2 m, 16 m rays", raw, 0.2f, 16.0f, merged,
                        &report);
        benchmark_lidar(device, options, "OS1-64 raw de-skewed 0.2 m, 16 m rays", raw, 0.2f, 16.0f,
                        merged, &report, &sweep);
        benchmark_lidar(device, options, "KITTI HDL-64 0.2 m, 50 m rays", kitti, 0.2f, 50.0f,
                        merged, &report);
      }
      if (!options.skip_rgbd) {
        const tools::DeviceRgbdFrames frames = tools::load_7scenes_frames(options.data, 70, device);
        for (float voxel_size : {0.05f, 0.02f}) {
          for (bool carving : {true, false})
            benchmark_rgbd(device, options, frames, voxel_size, carving, &report);
        }
      }
    }
    tools::publish_reports({&report}, options.output);
  });
}

// ESDF and mesh update times on real data, GPU and CPU twin. Prints two tables and writes
// docs/benchmarks/esdf.json and docs/benchmarks/mesh.json.
//
//   benchmark_esdf_mesh [--data DIR] [--device all|cuda|cpu] [--updates 30] [--skip-rgbd]
//
// After each integration (not timed) the incremental ESDF update and the incremental mesh update
// of the touched blocks (on the device) are timed, then the copy of the new block meshes to the
// host, separately; at the end one full ESDF recomputation and one full mesh extraction of the
// whole map. Cases: the Ouster OS1-64 scans at 0.2 m (the `arche` preset: truncation 3 voxels,
// 16 m rays) and 7-Scenes frames 0-69 at 5 cm, each mapped by a pipeline::Mapper configured as
// the TSDF benchmark configures it.
#include <iostream>
#include <string>
#include <vector>

#include "benchmark/benchmark_datasets.h"
#include "benchmark/benchmark_report.h"
#include "benchmark/benchmark_run.h"
#include "cli/command_line.h"
#include "covoxslam/core/device.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/pipeline/mapper.h"

namespace covox {
namespace {

struct Options {
  std::string data;
  std::string device = "all";
  int updates = 30;
  bool skip_rgbd = false;
};

Options parse(int argc, char** argv) {
  tools::CommandLine args(
      argc, argv,
      "usage: benchmark_esdf_mesh [--data DIR] [--device all|cuda|cpu] [--updates N]"
      " [--skip-rgbd]");
  Options options;
  options.data = args.text("--data", io::data_directory());
  options.device = args.text("--device", options.device);
  options.updates = static_cast<int>(args.positive_integer("--updates", options.updates));
  options.skip_rgbd = args.flag("--skip-rgbd");
  args.finish();
  return options;
}

struct Reports {
  tools::BenchmarkReport* esdf;
  tools::BenchmarkReport* mesh;
};

// Integrates frame (i mod frame_count) `updates` times; after each, times the incremental ESDF
// and mesh updates. The first pass over the frames is a warm-up and not recorded.
template <class IntegrateFrame>
void run_case(const std::string& name, pipeline::Mapper& mapper, size_t frame_count, int updates,
              IntegrateFrame&& integrate_frame, const Reports& reports) {
  const Stream& stream = mapper.stream();
  std::vector<double> esdf_ms, mesh_ms, mesh_download_ms, changed_blocks, meshed_blocks;
  const int warm_up = static_cast<int>(frame_count);
  for (int i = 0; i < warm_up + updates; ++i) {
    integrate_frame(static_cast<size_t>(i) % frame_count);
    integrators::EsdfUpdateStats esdf_stats;
    integrators::MeshUpdateStats mesh_stats;
    const double e = tools::stream_milliseconds(stream, [&] { esdf_stats = mapper.update_esdf(); });
    const double m = tools::stream_milliseconds(stream, [&] { mesh_stats = mapper.update_mesh(); });
    // What a node that publishes every frame pays on top: the new block meshes copied to the host.
    const double d = tools::stream_milliseconds(stream, [&] { mapper.block_meshes(); });
    if (i < warm_up) continue;
    esdf_ms.push_back(e);
    mesh_ms.push_back(m);
    mesh_download_ms.push_back(d);
    changed_blocks.push_back(static_cast<double>(esdf_stats.changed_blocks));
    meshed_blocks.push_back(static_cast<double>(mesh_stats.blocks_meshed));
  }
  const double full_esdf_ms = tools::stream_milliseconds(stream, [&] { mapper.update_esdf_all(); });
  size_t triangles = 0;
  const double full_mesh_ms = tools::stream_milliseconds(
      stream, [&] { triangles = mapper.extract_mesh().triangle_count(); });

  tools::print_stage_profile(name);
  reports.esdf->add(name, "incremental update (median)", tools::median_of(esdf_ms), "ms/frame");
  reports.esdf->add(name, "changed blocks per frame (median)", tools::median_of(changed_blocks),
                    "blocks");
  reports.esdf->add(name, "full update", full_esdf_ms, "ms");
  reports.esdf->add(name, "map blocks", static_cast<double>(mapper.map().block_count()), "blocks");
  reports.mesh->add(name, "incremental update (median)", tools::median_of(mesh_ms), "ms/frame");
  reports.mesh->add(name, "block meshes to the host (median)", tools::median_of(mesh_download_ms),
                    "ms/frame");
  reports.mesh->add(name, "blocks meshed per frame (median)", tools::median_of(meshed_blocks),
                    "blocks");
  reports.mesh->add(name, "full extraction (welded)", full_mesh_ms, "ms");
  reports.mesh->add(name, "triangles", static_cast<double>(triangles), "triangles");
}

// The `arche` preset's map (as benchmark_tsdf's OS1-64 0.2 m case) with a 2 m ESDF.
void benchmark_lidar(Device device, const Options& options, const Reports& reports) {
  const tools::DeviceScans scans = tools::load_ouster_scans(options.data, device);
  pipeline::MapperConfig config = pipeline::load_mapper_config({"arche"});
  config.device = device;
  config.map.voxel_size_m = 0.2f;
  config.tsdf.truncation_distance_m = 0.6f;
  config.esdf.esdf_max_distance_m = 2.0f;
  pipeline::Mapper mapper(config);
  run_case(
      std::string(to_string(device)) + " OS1-64 0.2 m, ESDF 2 m", mapper, scans.size(),
      options.updates,
      [&](size_t f) { mapper.integrate(scans.view(f), Eigen::Isometry3d::Identity()); }, reports);
}

// The `rgbd` preset's weighting at 5 cm with nvblox's truncation (as benchmark_tsdf's 5 cm case).
void benchmark_rgbd(Device device, const Options& options, const Reports& reports) {
  const tools::DeviceRgbdFrames frames = tools::load_7scenes_frames(options.data, 70, device);
  pipeline::MapperConfig config = pipeline::load_mapper_config({"rgbd"});
  config.device = device;
  config.map.voxel_size_m = 0.05f;
  config.map.voxels_per_side = 8;
  config.tsdf.truncation_distance_m = 0.2f;  // 4 voxels, nvblox's default
  config.tsdf.max_ray_length_m = 5.0f;
  config.esdf.esdf_max_distance_m = 2.0f;
  pipeline::Mapper mapper(config);
  run_case(
      std::string(to_string(device)) + " 7-Scenes 5 cm, ESDF 2 m", mapper, frames.size(),
      options.updates,
      [&](size_t f) { mapper.integrate_depth(frames.view(f), frames.T_world_camera[f]); }, reports);
}

}  // namespace
}  // namespace covox

int main(int argc, char** argv) {
  using namespace covox;
  const Options options = parse(argc, argv);
  return tools::run_benchmark("benchmark_esdf_mesh", [&] {
    const std::vector<Device> devices = tools::benchmark_devices(options.device);
    const std::string names = tools::describe_devices(devices);
    tools::BenchmarkReport esdf_report("esdf", names, argc, argv);
    tools::BenchmarkReport mesh_report("mesh", names, argc, argv);
    const Reports reports{&esdf_report, &mesh_report};
    for (Device device : devices) {
      std::cout << "ESDF and mesh on " << describe_device(device) << "..." << std::endl;
      benchmark_lidar(device, options, reports);
      if (!options.skip_rgbd) benchmark_rgbd(device, options, reports);
    }
    tools::publish_reports({&esdf_report, &mesh_report});
  });
}

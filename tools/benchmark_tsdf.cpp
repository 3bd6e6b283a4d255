// TSDF integration time per frame on real data, GPU and CPU twin. Prints a table and writes
// docs/benchmarks/tsdf.json.
//
//   benchmark_tsdf [--data DIR] [--device all|cuda|cpu] [--integrations 100]
//                  [--output docs/benchmarks/tsdf.json] [--skip-rgbd]
//
// Cases (issue 3): Ouster OS1-64 (newer_06) at 0.1 and 0.2 m voxels, truncation 3 voxels, 16 m
// rays (voxgraph's ARCHE setting); KITTI HDL-64 at 0.2 m with 50 m rays; 7-Scenes at 5 cm and
// 2 cm with colour, frames 0-69 (what nvblox was timed on).
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "benchmark_report.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/lidar_readers.h"
#include "covoxslam/io/rgbd_folder.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace {

struct Options {
  std::string data;
  std::string device = "all";
  int integrations = 100;
  std::string output = "docs/benchmarks/tsdf.json";
  bool skip_rgbd = false;
};

[[noreturn]] void usage(const std::string& problem) {
  std::cerr << "benchmark_tsdf: " << problem << "\n"
            << "usage: benchmark_tsdf [--data DIR] [--device all|cuda|cpu] [--integrations N]\n"
            << "       [--output docs/benchmarks/tsdf.json] [--skip-rgbd]\n";
  std::exit(2);
}

Options parse(int argc, char** argv) {
  Options options;
  options.data = io::data_directory();
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage(flag + " needs a value");
      return argv[++i];
    };
    if (flag == "--data") options.data = value();
    else if (flag == "--device") options.device = value();
    else if (flag == "--integrations") options.integrations = std::atoi(value().c_str());
    else if (flag == "--output") options.output = value();
    else if (flag == "--skip-rgbd") options.skip_rgbd = true;
    else usage("unknown option " + flag);
  }
  if (options.integrations <= 0) usage("--integrations must be positive");
  return options;
}

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

struct Timing {
  double median_ms = 0.0;
  double updates_per_s = 0.0;
  int64_t blocks = 0;
};

// Integrates `frames` round-robin into one map `integrations` times; the first pass over the
// frames is a warm-up (allocation of blocks and scratch), not timed.
template <class IntegrateFrame>
Timing time_integrations(const Stream& stream, size_t frame_count, int integrations, TsdfMap& map,
                         IntegrateFrame&& integrate_frame) {
  for (size_t f = 0; f < frame_count; ++f) integrate_frame(f);
  stream.synchronize();
  std::vector<double> times;
  int64_t updates = 0;
  double total_ms = 0.0;
  for (int i = 0; i < integrations; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const IntegrationStats stats = integrate_frame(static_cast<size_t>(i) % frame_count);
    stream.synchronize();
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    times.push_back(ms);
    total_ms += ms;
    updates += stats.voxel_updates;
  }
  return Timing{median(times), updates / (total_ms * 1e-3), map.block_count()};
}

void add_rows(tools::BenchmarkReport* report, const std::string& name, const Timing& t) {
  report->add(name, "median integration time", t.median_ms, "ms/frame");
  report->add(name, "voxel updates per second", t.updates_per_s / 1e6, "M/s");
  report->add(name, "allocated blocks", static_cast<double>(t.blocks), "blocks");
}

void benchmark_lidar(Device device, const Options& options, const std::string& label,
                     const std::vector<io::PointCloud>& scans, float voxel_size, float max_ray_m,
                     tools::BenchmarkReport* report) {
  const Stream stream(device);
  std::vector<Buffer<Vec3f>> device_scans;
  for (const auto& scan : scans) {
    std::vector<Vec3f> points(scan.points_m.size());
    for (size_t i = 0; i < points.size(); ++i) {
      points[i] = Vec3f(scan.points_m[i].x(), scan.points_m[i].y(), scan.points_m[i].z());
    }
    device_scans.push_back(Buffer<Vec3f>::from_host(device, points));
  }
  TsdfMap map(device, TsdfMapConfig{voxel_size, 16, {}});
  TsdfIntegratorConfig config;
  config.truncation_distance_m = 3.0f * voxel_size;
  config.max_ray_length_m = max_ray_m;
  config.use_const_weight = true;  // voxgraph's ARCHE configuration
  config.use_weight_dropoff = true;
  config.use_sparsity_compensation_factor = true;
  config.sparsity_compensation_factor = 20.0f;
  TsdfIntegrator integrator(config);
  const Timing timing = time_integrations(stream, device_scans.size(), options.integrations, map, [&](size_t f) {
    PointCloudView cloud{device_scans[f].data(), nullptr, static_cast<int64_t>(device_scans[f].size())};
    return integrator.integrate(map, cloud, Eigen::Isometry3d::Identity(), stream);
  });
  add_rows(report, std::string(to_string(device)) + " " + label, timing);
}

void benchmark_rgbd(Device device, const Options& options, const io::RgbdFolder& folder, float voxel_size,
                    tools::BenchmarkReport* report) {
  const Stream stream(device);
  const size_t frame_count = std::min<size_t>(70, folder.size());
  std::vector<Buffer<uint16_t>> depths;
  std::vector<Buffer<Rgb8>> colors;
  std::vector<Eigen::Isometry3d> poses;
  PinholeIntrinsics intrinsics;
  float units_per_m = 1000.0f;
  for (size_t f = 0; f < frame_count; ++f) {
    const io::RgbdFrame frame = folder.load(f);
    depths.push_back(Buffer<uint16_t>::from_host(device, frame.depth_raw));
    std::vector<Rgb8> rgb(frame.color.width * frame.color.height);
    for (size_t p = 0; p < rgb.size(); ++p) {
      rgb[p] = Rgb8{frame.color.rgb[3 * p], frame.color.rgb[3 * p + 1], frame.color.rgb[3 * p + 2]};
    }
    colors.push_back(Buffer<Rgb8>::from_host(device, rgb));
    poses.push_back(frame.T_world_camera);
    intrinsics = PinholeIntrinsics{float(frame.intrinsics.fx), float(frame.intrinsics.fy), float(frame.intrinsics.cx),
                                   float(frame.intrinsics.cy), frame.intrinsics.width, frame.intrinsics.height};
    units_per_m = frame.depth_units_per_m;
  }
  TsdfMap map(device, TsdfMapConfig{voxel_size, 8, {}});
  TsdfIntegratorConfig config;
  config.truncation_distance_m = 4.0f * voxel_size;  // nvblox's default truncation
  config.max_ray_length_m = 5.0f;
  TsdfIntegrator integrator(config);
  const Timing timing = time_integrations(stream, frame_count, options.integrations, map, [&](size_t f) {
    DepthImageView image;
    image.depth = depths[f].data();
    image.colors = colors[f].data();
    image.intrinsics = intrinsics;
    image.depth_units_per_m = units_per_m;
    image.invalid_value = 65535;
    return integrator.integrate_depth(map, image, poses[f], stream);
  });
  add_rows(report, std::string(to_string(device)) + " 7-Scenes " + std::to_string(int(voxel_size * 100 + 0.5)) +
                       " cm colour", timing);
}

}  // namespace
}  // namespace covox

int main(int argc, char** argv) {
  using namespace covox;
  const Options options = parse(argc, argv);
  try {
    std::vector<Device> devices;
    if (options.device == "all") {
      devices = available_devices();
      std::reverse(devices.begin(), devices.end());
    } else {
      devices = {select_device(parse_device_request(options.device))};
    }
    std::string names;
    for (Device d : devices) names += (names.empty() ? "" : "; ") + describe_device(d);
    tools::BenchmarkReport report("tsdf", names, argc, argv);
    std::vector<io::PointCloud> ouster, kitti;
    for (int i = 0; i < 3; ++i) {
      ouster.push_back(io::read_float_xyz_bin(options.data + "/lidar-scans/newer_06/deskewed_0" + std::to_string(i) + ".bin"));
    }
    for (int i = 0; i < 2; ++i) {
      kitti.push_back(io::read_float_xyz_bin(options.data + "/lidar-scans/kitti_00/00000" + std::to_string(i) + ".bin"));
    }
    for (Device device : devices) {
      std::cout << "TSDF on " << describe_device(device) << "..." << std::endl;
      benchmark_lidar(device, options, "OS1-64 0.2 m, 16 m rays", ouster, 0.2f, 16.0f, &report);
      benchmark_lidar(device, options, "OS1-64 0.1 m, 16 m rays", ouster, 0.1f, 16.0f, &report);
      benchmark_lidar(device, options, "KITTI HDL-64 0.2 m, 50 m rays", kitti, 0.2f, 50.0f, &report);
      if (!options.skip_rgbd) {
        const io::RgbdFolder folder = io::RgbdFolder::open_7scenes(options.data + "/7scenes-redkitchen");
        benchmark_rgbd(device, options, folder, 0.05f, &report);
        benchmark_rgbd(device, options, folder, 0.02f, &report);
      }
    }
    report.print_table(std::cout);
    report.write_json(options.output);
    std::cout << "wrote " << options.output << std::endl;
  } catch (const std::exception& error) {
    std::cerr << "benchmark_tsdf: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}

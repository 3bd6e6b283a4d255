#include "benchmark/benchmark_datasets.h"

#include <algorithm>
#include <cstring>
#include <iostream>

#include "covoxslam/core/error.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/lidar_bin_reader.h"
#include "covoxslam/io/rgbd_folder.h"

namespace covox {
namespace tools {
namespace {

DeviceScans load_scans(const std::vector<std::string>& paths, Device device) {
  DeviceScans scans;
  for (const std::string& path : paths) {
    // gtsam_points' dumps are x, y, z only; say so rather than let a 48-byte-multiple file guess.
    const io::PointCloud cloud = io::read_lidar_bin(path, io::BinPointLayout::kXyz);
    std::vector<Vec3f> points(cloud.size());
    for (size_t i = 0; i < points.size(); ++i) {
      points[i] = Vec3f(cloud.points_m[i].x(), cloud.points_m[i].y(), cloud.points_m[i].z());
    }
    scans.points.push_back(Buffer<Vec3f>::from_host(device, points));
  }
  return scans;
}

// A file of float32 values, one per point.
std::vector<float> read_float32_file(const std::string& path) {
  const std::vector<uint8_t> bytes = io::read_file_bytes(path);
  if (bytes.size() % sizeof(float) != 0)
    throw Error(path + ": " + std::to_string(bytes.size()) + " bytes is not a float32 array");
  std::vector<float> values(bytes.size() / sizeof(float));
  std::memcpy(values.data(), bytes.data(), bytes.size());
  return values;
}

}  // namespace

integrators::PointCloudView DeviceScans::view(size_t i,
                                              const integrators::SweepMotion* sweep) const {
  integrators::PointCloudView cloud;
  cloud.points = points[i].data();
  cloud.count = static_cast<int64_t>(points[i].size());
  if (sweep && i < times_s.size()) {
    cloud.times_s = times_s[i].data();
    cloud.sweep = *sweep;
  }
  return cloud;
}

integrators::DepthImageView DeviceRgbdFrames::view(size_t i) const {
  integrators::DepthImageView image;
  image.depth_m = depth_m[i].data();
  image.colors = color[i].size() > 0 ? color[i].data() : nullptr;
  image.intrinsics = intrinsics;
  return image;
}

DeviceScans load_ouster_scans(const std::string& data_directory, Device device) {
  const std::string folder = data_directory + "/lidar-scans/newer_06/";
  return load_scans(
      {folder + "deskewed_00.bin", folder + "deskewed_01.bin", folder + "deskewed_02.bin"}, device);
}

DeviceScans load_ouster_timed_scans(const std::string& data_directory, Device device) {
  const std::string folder = data_directory + "/lidar-scans/newer_06/";
  DeviceScans scans =
      load_scans({folder + "raw_00.bin", folder + "raw_01.bin", folder + "raw_02.bin"}, device);
  for (size_t i = 0; i < scans.size(); ++i) {
    const std::string path = folder + "times_0" + std::to_string(i) + ".bin";
    const std::vector<float> times = read_float32_file(path);
    if (times.size() != scans.points[i].size()) {
      throw Error(path + ": " + std::to_string(times.size()) + " times for " +
                  std::to_string(scans.points[i].size()) + " points");
    }
    scans.times_s.push_back(Buffer<float>::from_host(device, times));
  }
  return scans;
}

DeviceScans load_kitti_scans(const std::string& data_directory, Device device) {
  const std::string folder = data_directory + "/lidar-scans/kitti_00/";
  return load_scans({folder + "000000.bin", folder + "000001.bin"}, device);
}

DeviceRgbdFrames load_7scenes_frames(const std::string& data_directory, size_t count, Device device,
                                     bool with_color) {
  const io::RgbdFolder folder = io::RgbdFolder::open(data_directory + "/7scenes-redkitchen");
  DeviceRgbdFrames frames;
  const io::CameraIntrinsics& k = folder.intrinsics();
  frames.intrinsics = integrators::PinholeIntrinsics{static_cast<float>(k.fx),
                                                     static_cast<float>(k.fy),
                                                     static_cast<float>(k.cx),
                                                     static_cast<float>(k.cy),
                                                     k.width,
                                                     k.height};
  io::ReadStats stats;
  for (size_t f = 0; f < std::min(count, folder.size()); ++f) {
    const io::RgbdFrame frame = folder.read_frame(f, &stats, with_color);
    frames.depth_m.push_back(Buffer<float>::from_host(device, frame.depth.depth_m));
    std::vector<Rgb8> rgb;
    if (with_color && !frame.color.empty()) {
      if (frame.color.width != frame.depth.width || frame.color.height != frame.depth.height) {
        throw Error("7-Scenes frame " + std::to_string(f) +
                    ": colour and depth images differ in size");
      }
      rgb.resize(static_cast<size_t>(frame.color.width) * frame.color.height);
      for (size_t p = 0; p < rgb.size(); ++p) {
        rgb[p] =
            Rgb8{frame.color.rgb[3 * p], frame.color.rgb[3 * p + 1], frame.color.rgb[3 * p + 2]};
      }
    }
    frames.color.push_back(Buffer<Rgb8>::from_host(device, rgb));
    frames.T_world_camera.push_back(frame.T_world_camera);
  }
  return frames;
}

double median_of(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

void print_stage_profile(const std::string& case_name) {
  if (!StageProfiler::enabled()) return;
  std::cout << "stage profile: " << case_name << "\n" << StageProfiler::report() << std::endl;
  StageProfiler::reset();
}

}  // namespace tools
}  // namespace covox

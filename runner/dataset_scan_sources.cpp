#include "runner/dataset_scan_sources.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "covoxslam/core/error.h"
#include "covoxslam/io/lidar_bin_reader.h"
#include "covoxslam/io/pcd_reader.h"
#include "covoxslam/io/pose_file_readers.h"
#include "sim/sim_flight.h"

namespace covox {
namespace tools {

namespace fs = std::filesystem;

namespace {

std::string six_digits(int number) {
  char text[16];
  std::snprintf(text, sizeof(text), "%06d", number);
  return text;
}

// Every frame's reference pose without decoding any image (the drift needs the whole trajectory
// before the first frame is mapped).
std::vector<Eigen::Isometry3d> read_reference_poses(const io::RgbdFolder& folder) {
  std::vector<Eigen::Isometry3d> poses;
  if (folder.layout() == io::RgbdFolderLayout::kSevenScenes) {
    for (int number : folder.frame_numbers()) {
      poses.push_back(io::read_matrix4_pose_file(
          (fs::path(folder.path()) / ("frame-" + six_digits(number) + ".pose.txt")).string()));
    }
  } else {
    const std::string trajectory_path = (fs::path(folder.path()) / "traj.txt").string();
    const std::vector<Eigen::Isometry3d> all =
        io::read_matrix4_per_line_trajectory(trajectory_path);
    for (int number : folder.frame_numbers()) {
      if (number < 0 || static_cast<size_t>(number) >= all.size()) {
        throw Error("'" + trajectory_path + "' has no pose for frame " + std::to_string(number));
      }
      poses.push_back(all[number]);
    }
  }
  return poses;
}

}  // namespace

RgbdScanSource::RgbdScanSource(const std::string& path, const RgbdScanOptions& options)
    : options_(options), folder_(io::RgbdFolder::open(path)) {
  if (options_.pixel_stride < 1) throw Error("RGB-D pixel stride must be at least 1");
  if (!(options_.frame_rate_hz > 0.0)) throw Error("RGB-D frame rate must be positive");
  const std::vector<Eigen::Isometry3d> reference = read_reference_poses(folder_);
  size_t frames = reference.size();
  if (options_.max_frames > 0 && options_.max_frames < frames) frames = options_.max_frames;
  std::vector<sim::StampedIsometry> truth(frames);
  for (size_t i = 0; i < frames; ++i) {
    truth[i].stamp_s = folder_.frame_numbers()[i] / options_.frame_rate_hz;
    truth[i].pose = reference[i];
    reference_.poses.push_back(stamped_pose(truth[i].stamp_s, reference[i]));
  }
  reference_.has_orientations = true;
  reference_kind_ = ReferenceKind::kGroundTruth;
  // The simulator's odometry model, scaled to a hand-held camera: about 0.3 m over 10 s.
  sim::DriftConfig drift;
  drift.bias_velocity_m_per_s = Eigen::Vector3d(0.02, -0.015, 0.006);
  drift.yaw_bias_deg_per_s = 0.3;
  drift.translation_random_walk_m_per_sqrt_s = 0.01;
  drift.yaw_random_walk_deg_per_sqrt_s = 0.1;
  drift.min_final_drift_m = options_.min_final_drift_m * options_.drift_scale;
  drift = drift.scaled(options_.drift_scale);
  const std::vector<sim::StampedIsometry> odometry =
      sim::simulate_odometry(truth, drift, options_.drift_seed);
  for (const sim::StampedIsometry& pose : odometry) {
    stamps_s_.push_back(pose.stamp_s);
    odometry_.push_back(pose.pose);
  }
  final_drift_m_ = sim::final_drift_m(truth, odometry);
}

bool RgbdScanSource::next(SourceScan* scan) {
  if (next_frame_ >= odometry_.size()) return false;
  const size_t index = next_frame_++;
  const io::RgbdFrame frame = folder_.read_frame(index);
  const io::CameraIntrinsics& k = frame.intrinsics;
  const bool with_color = !frame.color.empty() && frame.color.width == frame.depth.width &&
                          frame.color.height == frame.depth.height;
  scan->stamp_s = stamps_s_[index];
  scan->T_odom_sensor = odometry_[index];
  scan->points_sensor_m.clear();
  scan->colors.clear();
  const int stride = options_.pixel_stride;
  for (int row = 0; row < frame.depth.height; row += stride) {
    for (int column = 0; column < frame.depth.width; column += stride) {
      const float depth_m = frame.depth.at(row, column);
      if (!(depth_m > 0.0f)) continue;
      if (options_.max_depth_m > 0.0 && depth_m > options_.max_depth_m) continue;
      scan->points_sensor_m.emplace_back(static_cast<float>((column - k.cx) * depth_m / k.fx),
                                         static_cast<float>((row - k.cy) * depth_m / k.fy),
                                         depth_m);
      if (with_color) {
        const std::array<uint8_t, 3> rgb = frame.color.at(row, column);
        scan->colors.push_back(Rgb8{rgb[0], rgb[1], rgb[2]});
      }
    }
  }
  return true;
}

std::string RgbdScanSource::describe() const {
  std::ostringstream text;
  text << "RGB-D folder " << folder_.path() << ", " << odometry_.size() << " frames at "
       << options_.frame_rate_hz << " Hz, every " << options_.pixel_stride
       << (options_.pixel_stride == 1 ? "" : "th")
       << " pixel in both directions; odometry = reference poses with a drift of " << final_drift_m_
       << " m at the end (seed " << options_.drift_seed << ")";
  return text.str();
}

LidarKeyframeScanSource::LidarKeyframeScanSource(const std::string& path,
                                                 const LidarKeyframeScanOptions& options)
    : KeyframeFolderScanSource(path, options) {
  const fs::path folder(path);
  const std::vector<Eigen::Isometry3d> odometry =
      io::read_kitti_pose_file((folder / "odom_poses.txt").string());
  const std::string times_path = (folder / "times.txt").string();
  std::ifstream times(times_path);
  if (!times) throw Error("cannot open '" + times_path + "'");
  double stamp_s;
  while (times >> stamp_s) stamps_s_.push_back(stamp_s);
  if (stamps_s_.size() != odometry.size()) {
    throw Error("'" + times_path + "' has " + std::to_string(stamps_s_.size()) +
                " stamps, odom_poses.txt " + std::to_string(odometry.size()) + " poses");
  }
  size_t count = odometry.size();
  if (options_.max_scans > 0 && options_.max_scans < count) count = options_.max_scans;
  stamps_s_.resize(count);
  odometry_.assign(odometry.begin(), odometry.begin() + count);
  const std::string reference_path = (folder / "optimized_poses.txt").string();
  if (fs::exists(reference_path)) {
    const std::vector<Eigen::Isometry3d> reference = io::read_kitti_pose_file(reference_path);
    for (size_t i = 0; i < std::min(count, reference.size()); ++i)
      reference_.poses.push_back(stamped_pose(stamps_s_[i], reference[i]));
    reference_.has_orientations = true;
    reference_kind_ = ReferenceKind::kOtherEstimate;
  }
  if (options_.added_drift_m < 0.0) {
    throw Error("added odometry drift must be >= 0 m, got " +
                std::to_string(options_.added_drift_m));
  }
  if (options_.added_drift_m > 0.0) add_drift(options_.added_drift_m, 1.0);
}

namespace {

// The scan's points: those of `cloud` at least `min_range_m` from the sensor, without colours.
void keep_points_beyond(const io::PointCloud& cloud, double min_range_m, SourceScan* scan) {
  scan->points_sensor_m.clear();
  scan->colors.clear();
  const float min_range_squared = static_cast<float>(min_range_m * min_range_m);
  for (const Eigen::Vector3f& p : cloud.points_m) {
    if (p.squaredNorm() >= min_range_squared)
      scan->points_sensor_m.emplace_back(p.x(), p.y(), p.z());
  }
}

}  // namespace

// The simulator's odometry model as it is (a vehicle's odometry), scaled to the asked drift.
void KeyframeFolderScanSource::add_drift(double min_final_drift_m, double drift_scale) {
  std::vector<sim::StampedIsometry> given(odometry_.size());
  for (size_t i = 0; i < given.size(); ++i) given[i] = {stamps_s_[i], odometry_[i]};
  sim::DriftConfig drift;
  drift.min_final_drift_m = min_final_drift_m * drift_scale;
  drift = drift.scaled(drift_scale);
  const std::vector<sim::StampedIsometry> drifted =
      sim::simulate_odometry(given, drift, options_.drift_seed);
  for (size_t i = 0; i < drifted.size(); ++i) odometry_[i] = drifted[i].pose;
  final_drift_m_ = sim::final_drift_m(given, drifted);
}

bool KeyframeFolderScanSource::next(SourceScan* scan) {
  while (next_scan_ < odometry_.size()) {
    const size_t index = next_scan_++;
    try {
      const io::PointCloud cloud = read_cloud(index);
      scan->stamp_s = stamps_s_[index];
      scan->T_odom_sensor = odometry_[index];
      keep_points_beyond(cloud, options_.min_range_m, scan);
      return true;
    } catch (const Error& error) {
      log_dropped_scan(++dropped_, error.what());
    }
  }
  return false;
}

io::PointCloud LidarKeyframeScanSource::read_cloud(size_t index) const {
  return io::read_pcd(
      (fs::path(path_) / "Scans" / (six_digits(static_cast<int>(index)) + ".pcd")).string());
}

std::string LidarKeyframeScanSource::describe() const {
  std::ostringstream text;
  text << "LiDAR keyframes " << path_ << ", " << odometry_.size()
       << " scans, odometry odom_poses.txt";
  if (options_.added_drift_m > 0.0) {
    text << " with an added drift of " << final_drift_m_ << " m at the end (seed "
         << options_.drift_seed << ")";
  }
  if (reference_kind_ == ReferenceKind::kOtherEstimate)
    text << ", reference optimized_poses.txt (not ground truth)";
  return text.str();
}

double LidarKeyframeScanSource::duration_s() const {
  return stamps_s_.size() < 2 ? 0.0 : stamps_s_.back() - stamps_s_.front();
}

namespace {

// graph.txt: 'vN x y z qx qy qz qw' per keyframe, N counting from 0.
std::vector<Eigen::Isometry3d> read_keyframe_graph(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw Error("cannot open '" + path + "'");
  std::vector<Eigen::Isometry3d> poses;
  std::string line;
  while (std::getline(file, line)) {
    if (line.empty()) continue;
    std::istringstream fields(line);
    std::string name;
    double x, y, z, qx, qy, qz, qw;
    if (!(fields >> name >> x >> y >> z >> qx >> qy >> qz >> qw) ||
        name != "v" + std::to_string(poses.size())) {
      throw Error("'" + path + "': expected 'v" + std::to_string(poses.size()) +
                  " x y z qx qy qz qw', got '" + line + "'");
    }
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
    pose.translation() = Eigen::Vector3d(x, y, z);
    poses.push_back(pose);
  }
  if (poses.empty()) throw Error("'" + path + "' holds no keyframe");
  return poses;
}

}  // namespace

LidarKeyframeGraphScanSource::LidarKeyframeGraphScanSource(const std::string& path,
                                                           const LidarKeyframeScanOptions& options)
    : KeyframeFolderScanSource(path, options) {
  if (!(options_.keyframe_interval_s > 0.0)) throw Error("keyframe interval must be positive");
  const std::vector<Eigen::Isometry3d> given =
      read_keyframe_graph((fs::path(path) / "graph.txt").string());
  size_t count = given.size();
  if (options_.max_scans > 0 && options_.max_scans < count) count = options_.max_scans;
  std::vector<sim::StampedIsometry> truth(count);
  for (size_t i = 0; i < count; ++i) {
    truth[i].stamp_s = static_cast<double>(i) * options_.keyframe_interval_s;
    truth[i].pose = given[i];
    reference_.poses.push_back(stamped_pose(truth[i].stamp_s, given[i]));
  }
  reference_.has_orientations = true;
  reference_kind_ = ReferenceKind::kOtherEstimate;
  for (const sim::StampedIsometry& pose : truth) {
    stamps_s_.push_back(pose.stamp_s);
    odometry_.push_back(pose.pose);
  }
  add_drift(options_.min_final_drift_m, options_.drift_scale);
}

io::PointCloud LidarKeyframeGraphScanSource::read_cloud(size_t index) const {
  return io::read_lidar_bin(
      (fs::path(path_) / six_digits(static_cast<int>(index)) / "points.bin").string(),
      io::BinPointLayout::kXyz);
}

std::string LidarKeyframeGraphScanSource::describe() const {
  std::ostringstream text;
  text << "LiDAR keyframe graph " << path_ << ", " << odometry_.size() << " keyframes "
       << options_.keyframe_interval_s << " s apart; odometry = graph.txt poses (not ground truth)"
       << " with a drift of " << final_drift_m_ << " m at the end (seed " << options_.drift_seed
       << ")";
  return text.str();
}

double LidarKeyframeGraphScanSource::duration_s() const {
  return static_cast<double>(stamps_s_.size()) * options_.keyframe_interval_s;
}

std::string default_preset(const ScanSource& source) {
  if (dynamic_cast<const RgbdScanSource*>(&source)) return "rgbd";
  if (dynamic_cast<const KeyframeFolderScanSource*>(&source)) return "lidar_keyframes";
  return "arche";
}

std::unique_ptr<ScanSource> open_dataset_scan_source(
    const std::string& path, const RgbdScanOptions& rgbd_options,
    const LidarKeyframeScanOptions& lidar_options) {
  const fs::path folder(path);
  if (!fs::is_directory(folder)) throw Error("dataset folder '" + path + "' does not exist");
  if (fs::exists(folder / "odom_poses.txt") && fs::is_directory(folder / "Scans")) {
    return std::make_unique<LidarKeyframeScanSource>(path, lidar_options);
  }
  if (fs::exists(folder / "graph.txt") && fs::exists(folder / "000000" / "points.bin")) {
    return std::make_unique<LidarKeyframeGraphScanSource>(path, lidar_options);
  }
  // RgbdFolder::open names the RGB-D layouts it looked for when the folder holds neither.
  try {
    return std::make_unique<RgbdScanSource>(path, rgbd_options);
  } catch (const Error& error) {
    throw Error(std::string(error.what()) +
                "; nor LiDAR keyframes (Scans/*.pcd with odom_poses.txt, or NNNNNN/points.bin with "
                "graph.txt)");
  }
}

}  // namespace tools
}  // namespace covox

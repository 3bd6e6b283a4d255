#pragma once
// Scans from the dataset folders of the shared data (the data folder's README.md): RGB-D folders
// (7-Scenes, 3DMatch, Replica), LiDAR keyframe folders in the MulRan layout and LiDAR keyframe
// graphs, each source documented at its class. Where a dataset has no odometry, the odometry is
// its poses perturbed by the simulator's drift model (a deterministic random walk with bias in
// x, y, z and yaw about the world z axis) of at least `min_final_drift_m` at the end.
#include <memory>
#include <string>
#include <vector>

#include "covoxslam/io/rgbd_folder.h"
#include "covoxslam/io/sensor_data.h"
#include "runner/scan_source.h"

namespace covox {
namespace tools {

struct RgbdScanOptions {
  int pixel_stride = 2;
  double frame_rate_hz = 30.0;  // Kinect v1
  double min_final_drift_m = 0.3;
  uint64_t drift_seed = 1;
  // The drift model and min_final_drift_m multiplied by this (0: odometry = reference).
  double drift_scale = 1.0;
  double max_depth_m = 0.0;  // 0: every valid depth
  size_t max_frames = 0;     // 0: all
};

// An RGB-D folder (io/rgbd_folder.h): each depth image back-projected into a point cloud in the
// camera frame (every `pixel_stride`-th pixel in both directions, with its colour). The dataset's
// poses are the reference (ground truth); the odometry is those poses with the drift. Frame
// numbers / `frame_rate_hz` are the stamps.
class RgbdScanSource : public ScanSource {
 public:
  // Throws covox::Error when the folder is not an RGB-D dataset (io::RgbdFolder::open's message).
  RgbdScanSource(const std::string& path, const RgbdScanOptions& options);
  size_t size() const override { return odometry_.size(); }
  bool next(SourceScan* scan) override;
  std::string describe() const override;
  double duration_s() const override { return size() / options_.frame_rate_hz; }
  // The drift the odometry ends with (m).
  double final_drift_m() const { return final_drift_m_; }

 private:
  RgbdScanOptions options_;
  io::RgbdFolder folder_;
  std::vector<double> stamps_s_;
  std::vector<Eigen::Isometry3d> odometry_;
  double final_drift_m_ = 0.0;
  size_t next_frame_ = 0;
};

struct LidarKeyframeScanOptions {
  double min_range_m = 2.0;  // the car's own body and the sensor mount
  size_t max_scans = 0;      // 0: all
  // Keyframe graphs only (the MulRan layout has its own stamps).
  double keyframe_interval_s = 10.0;
  double min_final_drift_m = 0.3;
  uint64_t drift_seed = 1;
  double drift_scale = 1.0;
  // MulRan layout only: > 0 adds the simulator's drift (seed drift_seed) to the recorded
  // odometry, so that it ends at least this far from where it was recorded; 0 keeps the odometry
  // as recorded.
  double added_drift_m = 0.0;
};

// A folder of LiDAR keyframes: the stamps and odometry poses its constructor reads, and one cloud
// per keyframe read by read_cloud(). A cloud that cannot be read drops its keyframe (logged and
// counted) and the next one is read.
class KeyframeFolderScanSource : public ScanSource {
 public:
  size_t size() const override { return odometry_.size(); }
  bool next(SourceScan* scan) override;
  // How far the drift this source added moves the odometry's last pose (0: none added).
  double final_drift_m() const { return final_drift_m_; }

 protected:
  KeyframeFolderScanSource(const std::string& path, const LidarKeyframeScanOptions& options)
      : path_(path), options_(options) {}
  // The keyframe's points in the sensor frame; throws covox::Error when they cannot be read.
  virtual io::PointCloud read_cloud(size_t index) const = 0;

  // odometry_ (stamped by stamps_s_) with the simulator's drift of at least min_final_drift_m
  // at the end, its rates times drift_scale (0: unchanged); sets final_drift_m_.
  void add_drift(double min_final_drift_m, double drift_scale);

  std::string path_;
  LidarKeyframeScanOptions options_;
  std::vector<double> stamps_s_;
  std::vector<Eigen::Isometry3d> odometry_;
  double final_drift_m_ = 0.0;  // the drift add_drift gave the odometry
  size_t next_scan_ = 0;
};

// MulRan's layout: `Scans/NNNNNN.pcd` (point clouds in the sensor frame), `odom_poses.txt` (KITTI
// format, sensor-to-world odometry: the odometry, with added_drift_m of drift added when asked),
// `optimized_poses.txt` (another SLAM system's estimate: the reference, NOT ground truth) and
// `times.txt` (one stamp per scan, seconds).
class LidarKeyframeScanSource : public KeyframeFolderScanSource {
 public:
  // Throws covox::Error naming the missing or inconsistent file.
  LidarKeyframeScanSource(const std::string& path, const LidarKeyframeScanOptions& options);
  std::string describe() const override;
  double duration_s() const override;

 private:
  io::PointCloud read_cloud(size_t index) const override;
};

// A keyframe graph (the lidar-scans dumps): `NNNNNN/points.bin` (float32 x, y, z per point in the
// sensor frame) and `graph.txt` (one line per keyframe, 'vN x y z qx qy qz qw', the
// sensor-to-world pose another SLAM system gave it: the reference, NOT ground truth). The
// keyframes carry no stamps: keyframe N is stamped N * keyframe_interval_s. The odometry is the
// given poses with the drift of at least min_final_drift_m at the end, times drift_scale (0: the
// given poses themselves).
class LidarKeyframeGraphScanSource : public KeyframeFolderScanSource {
 public:
  // Throws covox::Error naming the missing or inconsistent file.
  LidarKeyframeGraphScanSource(const std::string& path, const LidarKeyframeScanOptions& options);
  std::string describe() const override;
  double duration_s() const override;

 private:
  io::PointCloud read_cloud(size_t index) const override;
};

// Opens `path` as whichever dataset layout it holds (RGB-D folder, LiDAR keyframes or a LiDAR
// keyframe graph); throws
// covox::Error naming the folder and the layouts looked for otherwise.
std::unique_ptr<ScanSource> open_dataset_scan_source(const std::string& path,
                                                     const RgbdScanOptions& rgbd_options,
                                                     const LidarKeyframeScanOptions& lidar_options);

// The preset (config/NAME.yaml) an input of this kind is mapped with when none is given: `rgbd`
// for RGB-D folders, `lidar_keyframes` for keyframe folders, `arche` for flights (bags and
// the simulator). run_slam and the accuracy benchmark both choose through it.
std::string default_preset(const ScanSource& source);

}  // namespace tools
}  // namespace covox

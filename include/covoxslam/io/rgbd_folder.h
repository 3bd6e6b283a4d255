#pragma once
// RGB-D dataset folders as the shared data holds them (the data folder's README.md):
//  * 7-Scenes / 3DMatch: `frame-NNNNNN.depth.png` (uint16 millimetres; 0 and 65535 invalid),
//    `frame-NNNNNN.color.jpg` or `.color.png`, `frame-NNNNNN.pose.txt` (4x4 camera-to-world),
//    and `camera-intrinsics.txt` (3x3 K) in the folder or its parent (3DMatch keeps it one level
//    up, next to `seq-01/`).
//  * Replica (nvblox test data): `results/depthNNNNNN.png` (uint16, `scale` units per metre),
//    `results/frameNNNNNN.jpg`, `traj.txt` (one row-major 4x4 camera-to-world per line), and
//    `cam_params.json` in the folder or its parent.
// Frames are listed from the depth files present, sorted by frame number; a frame whose pose or
// colour image is missing throws when it is read, naming the file.
#include <cstddef>
#include <string>
#include <vector>

#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {

enum class RgbdFolderLayout { kSevenScenes, kReplica };

class RgbdFolder {
 public:
  // Detects the layout of `path` and lists its frames. Throws covox::Error naming the folder when
  // it holds neither layout, has no depth frames, or its intrinsics cannot be read.
  static RgbdFolder open(const std::string& path);

  RgbdFolderLayout layout() const { return layout_; }
  const std::string& path() const { return path_; }
  size_t size() const { return frame_numbers_.size(); }
  // The dataset's own frame numbers (e.g. 0, 1, 2, 116, 422 for nvblox's 3DMatch sample).
  const std::vector<int>& frame_numbers() const { return frame_numbers_; }
  const CameraIntrinsics& intrinsics() const { return intrinsics_; }
  // Raw depth units per metre: 1000 for 7-Scenes/3DMatch, `scale` (6553.5) for Replica.
  double depth_units_per_m() const { return depth_units_per_m_; }

  // Reads frame `index` (0 .. size()-1): depth in metres (invalid pixels 0, counted in `stats`),
  // colour unless `with_color` is false, the pose (re-orthonormalised and counted when slightly
  // off), and the frame number as timestamp_s when the dataset has no times.
  RgbdFrame read_frame(size_t index, ReadStats* stats = nullptr, bool with_color = true) const;

 private:
  RgbdFolderLayout layout_ = RgbdFolderLayout::kSevenScenes;
  std::string path_;
  std::vector<int> frame_numbers_;
  CameraIntrinsics intrinsics_;
  double depth_units_per_m_ = 1000.0;
  std::vector<Eigen::Isometry3d> replica_trajectory_;  // Replica only: all of traj.txt
};

}  // namespace io
}  // namespace covox

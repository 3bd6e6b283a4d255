#pragma once
// What the registration tools read to put a run's submaps at their true poses: each submap's
// first and last scan stamps from a `run_slam --graph` dump, and the true pose at a stamp.
#include <cstdint>
#include <map>
#include <string>

#include <Eigen/Geometry>

#include "covoxslam/io/trajectory_io.h"

namespace covox {
namespace eval {

struct SubmapSpan {
  double start_s = 0.0;  // the submap's first scan
  double end_s = 0.0;    // its last scan
};

// The 'submap ID START_S END_S ...' lines of a graph dump, by id. Throws covox::Error when the
// file cannot be opened or has no such line.
std::map<int64_t, SubmapSpan> read_submap_spans(const std::string& path);

// The pose of `truth` at `stamp_s` (interpolate_pose); throws covox::Error naming `path` when the
// trajectory does not cover the stamp.
Eigen::Isometry3d true_pose_at(const io::Trajectory& truth, double stamp_s,
                               const std::string& path);

}  // namespace eval
}  // namespace covox

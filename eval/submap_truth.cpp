#include "eval/submap_truth.h"

#include <fstream>
#include <sstream>

#include "covoxslam/core/error.h"
#include "eval/trajectory_evaluation.h"

namespace covox {
namespace eval {

std::map<int64_t, SubmapSpan> read_submap_spans(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw Error("cannot open graph dump " + path);
  std::map<int64_t, SubmapSpan> spans;
  std::string line;
  while (std::getline(file, line)) {
    std::istringstream fields(line);
    std::string kind;
    int64_t id = 0;
    SubmapSpan span;
    if (fields >> kind && kind == "submap" && fields >> id >> span.start_s >> span.end_s)
      spans[id] = span;
  }
  if (spans.empty()) throw Error("graph dump " + path + " has no 'submap' lines");
  return spans;
}

Eigen::Isometry3d true_pose_at(const io::Trajectory& truth, double stamp_s,
                               const std::string& path) {
  io::StampedPose stamped;
  if (!interpolate_pose(truth, stamp_s, &stamped)) {
    throw Error(path + " does not cover stamp " + std::to_string(stamp_s));
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = stamped.orientation.toRotationMatrix();
  pose.translation() = stamped.position_m;
  return pose;
}

}  // namespace eval
}  // namespace covox

#pragma once
// Trajectories in the TUM RGB-D text format, one pose per line:
//
//   timestamp tx ty tz qx qy qz qw      (seconds, metres, unit quaternion x y z w)
//
// Lines starting with '#' and blank lines are ignored. Position-only ground truth (RTK fixes, as
// in the ARCHE flights) is written as `timestamp tx ty tz`; every line of one file must then have
// the same form. Timestamps must increase strictly: evaluation interpolates between neighbours
// and would silently pick wrong pairs in an unsorted file.
#include <iosfwd>
#include <string>
#include <vector>

#include <Eigen/Geometry>

namespace covox {
namespace io {

struct StampedPose {
  double timestamp_s = 0.0;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  // Identity when the trajectory has no orientations.
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
};

struct Trajectory {
  std::vector<StampedPose> poses;
  // False for position-only files (4 columns); orientations are then identity placeholders.
  bool has_orientations = true;

  size_t size() const { return poses.size(); }
  bool empty() const { return poses.empty(); }
};

// Reads a TUM file. Throws covox::Error naming the file and line for: a missing file, a line with
// a wrong number of columns or a token that is not a finite number, a quaternion far from unit
// length, a mix of 4- and 8-column lines, and a timestamp not greater than the one before it.
Trajectory read_tum_trajectory(const std::string& path);

// The same, from a stream; `source_name` is what error messages call it.
Trajectory parse_tum_trajectory(std::istream& input, const std::string& source_name);

// Writes with enough digits that reading back gives the same doubles. The write goes to a
// temporary file that is renamed, so a crash never leaves a half-written trajectory behind.
void write_tum_trajectory(const std::string& path, const Trajectory& trajectory);
void write_tum_trajectory(std::ostream& output, const Trajectory& trajectory);

}  // namespace io
}  // namespace covox

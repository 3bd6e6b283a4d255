#include "covoxslam/io/trajectory_io.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <locale>
#include <sstream>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/core/number_text.h"
#include "covoxslam/io/file_bytes.h"

namespace covox {
namespace io {
namespace {

constexpr int kPositionOnlyColumns = 4;  // timestamp tx ty tz
constexpr int kFullPoseColumns = 8;      // timestamp tx ty tz qx qy qz qw
// Files written with 6 decimals have quaternion norms within ~1e-6 of one; a norm off by more
// than this means the columns are not a quaternion (wrong format, shifted columns).
constexpr double kQuaternionNormTolerance = 1e-2;

std::string location(const std::string& source_name, int line_number) {
  return source_name + ":" + std::to_string(line_number) + ": ";
}

bool is_comment_or_blank(const std::string& line) {
  for (char c : line) {
    if (c == '#') return true;
    if (c != ' ' && c != '\t' && c != '\r') return false;
  }
  return true;
}

}  // namespace

Trajectory parse_tum_trajectory(std::istream& input, const std::string& source_name) {
  Trajectory trajectory;
  int columns_of_file = 0;  // fixed by the first pose line
  int first_pose_line = 0;
  int previous_line = 0;
  std::string line;
  int line_number = 0;
  while (std::getline(input, line)) {
    ++line_number;
    if (is_comment_or_blank(line)) continue;

    std::istringstream tokens(line);
    std::vector<double> values;
    std::string token;
    while (tokens >> token) {
      double value = 0.0;
      if (!parse_double(token, &value)) {
        throw Error(location(source_name, line_number) + "'" + token + "' is not a number");
      }
      if (!std::isfinite(value)) {
        throw Error(location(source_name, line_number) + "'" + token +
                    "' is not a finite number (NaN or Inf)");
      }
      values.push_back(value);
    }
    const int columns = static_cast<int>(values.size());
    if (columns != kFullPoseColumns && columns != kPositionOnlyColumns) {
      throw Error(location(source_name, line_number) + "expected 8 numbers " +
                  "'timestamp tx ty tz qx qy qz qw' (or 4 for positions only), found " +
                  std::to_string(columns));
    }
    if (columns_of_file == 0) {
      columns_of_file = columns;
      first_pose_line = line_number;
      trajectory.has_orientations = columns == kFullPoseColumns;
    } else if (columns != columns_of_file) {
      throw Error(location(source_name, line_number) + "has " + std::to_string(columns) +
                  " numbers but line " + std::to_string(first_pose_line) + " has " +
                  std::to_string(columns_of_file) + "; a file must be all poses or all positions");
    }

    StampedPose pose;
    pose.timestamp_s = values[0];
    pose.position_m = Eigen::Vector3d(values[1], values[2], values[3]);
    if (columns == kFullPoseColumns) {
      // TUM order is qx qy qz qw; Eigen's constructor takes w first.
      Eigen::Quaterniond orientation(values[7], values[4], values[5], values[6]);
      const double norm = orientation.norm();
      if (std::abs(norm - 1.0) > kQuaternionNormTolerance) {
        throw Error(location(source_name, line_number) + "quaternion (qx qy qz qw) has norm " +
                    std::to_string(norm) + ", expected 1");
      }
      orientation.normalize();
      pose.orientation = orientation;
    }
    if (!trajectory.poses.empty() && !(pose.timestamp_s > trajectory.poses.back().timestamp_s)) {
      std::ostringstream message;
      message.precision(std::numeric_limits<double>::max_digits10);
      message << location(source_name, line_number) << "timestamp " << pose.timestamp_s
              << " is not after " << trajectory.poses.back().timestamp_s << " on line "
              << previous_line << "; poses must be sorted by time without duplicates";
      throw Error(message.str());
    }
    trajectory.poses.push_back(pose);
    previous_line = line_number;
  }
  if (input.bad())
    throw Error(source_name + ": read error after line " + std::to_string(line_number));
  return trajectory;
}

Trajectory read_tum_trajectory(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw Error(path + ": cannot open trajectory file");
  return parse_tum_trajectory(file, path);
}

void write_tum_trajectory(std::ostream& output, const Trajectory& trajectory) {
  // The classic locale keeps '.' as the decimal point whatever the user's locale says.
  output.imbue(std::locale::classic());
  output.precision(std::numeric_limits<double>::max_digits10);
  output << (trajectory.has_orientations ? "# timestamp tx ty tz qx qy qz qw\n"
                                         : "# timestamp tx ty tz\n");
  for (const StampedPose& pose : trajectory.poses) {
    output << pose.timestamp_s << ' ' << pose.position_m.x() << ' ' << pose.position_m.y() << ' '
           << pose.position_m.z();
    if (trajectory.has_orientations) {
      output << ' ' << pose.orientation.x() << ' ' << pose.orientation.y() << ' '
             << pose.orientation.z() << ' ' << pose.orientation.w();
    }
    output << '\n';
  }
}

void write_tum_trajectory(const std::string& path, const Trajectory& trajectory) {
  write_file_replacing(path, "write_tum_trajectory", /*binary=*/false,
                       [&](std::ostream& file) { write_tum_trajectory(file, trajectory); });
}

}  // namespace io
}  // namespace covox

#include "covoxslam/io/pose_file_readers.h"

#include <charconv>

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/internal/text_numbers.h"

namespace covox {
namespace io {
namespace {

std::string location(const std::string& path, int line_number) {
  return path + ":" + std::to_string(line_number);
}

void require_value_count(const NumberLine& line, size_t expected, const std::string& path,
                         const char* format) {
  if (line.values.size() != expected) {
    throw Error(location(path, line.line_number) + ": expected " + std::to_string(expected) +
                " numbers (" + format + "), found " + std::to_string(line.values.size()));
  }
}

// Rows of `values` (row-major, 12 or 16 numbers) as a 4x4 matrix; 12 numbers get (0 0 0 1).
Eigen::Matrix4d matrix_from_row_major(const std::vector<double>& values) {
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();
  const int rows = static_cast<int>(values.size()) / 4;
  for (int row = 0; row < rows; ++row) {
    for (int column = 0; column < 4; ++column) matrix(row, column) = values[4 * row + column];
  }
  return matrix;
}

std::vector<Eigen::Isometry3d> read_row_major_per_line(const std::string& path,
                                                       size_t numbers_per_line, const char* format,
                                                       ReadStats* stats,
                                                       const PoseTolerances& tolerances) {
  const std::vector<NumberLine> lines = parse_number_lines(read_text_file(path), path);
  std::vector<Eigen::Isometry3d> poses;
  poses.reserve(lines.size());
  for (const NumberLine& line : lines) {
    require_value_count(line, numbers_per_line, path, format);
    poses.push_back(make_rigid_pose(matrix_from_row_major(line.values),
                                    location(path, line.line_number), stats, tolerances));
  }
  return poses;
}

}  // namespace

Eigen::Isometry3d read_matrix4_pose_file(const std::string& path, ReadStats* stats,
                                         const PoseTolerances& tolerances) {
  const std::vector<NumberLine> lines = parse_number_lines(read_text_file(path), path);
  if (lines.size() != 4) {
    throw Error(path + ": expected 4 rows of a 4x4 pose matrix, found " +
                std::to_string(lines.size()) + " non-empty lines");
  }
  std::vector<double> values;
  for (const NumberLine& line : lines) {
    require_value_count(line, 4, path, "one row of a 4x4 matrix");
    values.insert(values.end(), line.values.begin(), line.values.end());
  }
  // Errors name the first line: the matrix is only judged as a whole.
  return make_rigid_pose(matrix_from_row_major(values), location(path, lines.front().line_number),
                         stats, tolerances);
}

std::vector<Eigen::Isometry3d> read_matrix4_per_line_trajectory(const std::string& path,
                                                                ReadStats* stats,
                                                                const PoseTolerances& tolerances) {
  return read_row_major_per_line(path, 16, "a row-major 4x4 matrix", stats, tolerances);
}

std::vector<Eigen::Isometry3d> read_kitti_pose_file(const std::string& path, ReadStats* stats,
                                                    const PoseTolerances& tolerances) {
  return read_row_major_per_line(path, 12, "KITTI: the top 3x4 of a row-major pose matrix", stats,
                                 tolerances);
}

std::vector<KeyframePose> read_keyframe_graph_file(const std::string& path, ReadStats* stats,
                                                   const PoseTolerances& tolerances) {
  const std::string text = read_text_file(path);
  std::vector<KeyframePose> keyframes;
  for (const TokenLine& line : split_token_lines(text)) {
    const std::vector<std::string_view>& tokens = line.tokens;
    const std::string where = location(path, line.line_number);
    if (tokens.size() != 8) {
      throw Error(where + ": expected 'vN x y z qx qy qz qw' (8 fields), found " +
                  std::to_string(tokens.size()));
    }
    KeyframePose keyframe;
    const std::string_view label = tokens[0];
    const char* digits_end = label.data() + label.size();
    if (label.size() < 2 || label[0] != 'v' ||
        std::from_chars(label.data() + 1, digits_end, keyframe.id).ptr != digits_end) {
      throw Error(where + ": keyframe label '" + std::string(label) + "' is not of the form vN");
    }
    double numbers[7];
    for (int i = 0; i < 7; ++i) {
      if (!parse_double(tokens[i + 1], &numbers[i])) {
        throw Error(where + ": '" + std::string(tokens[i + 1]) + "' is not a number");
      }
    }
    keyframe.T_world_sensor = make_rigid_pose_from_quaternion(
        Eigen::Vector3d(numbers[0], numbers[1], numbers[2]), numbers[3], numbers[4], numbers[5],
        numbers[6], where, stats, tolerances);
    keyframes.push_back(keyframe);
  }
  return keyframes;
}

}  // namespace io
}  // namespace covox

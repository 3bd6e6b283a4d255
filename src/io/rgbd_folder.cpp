#include "covoxslam/io/rgbd_folder.h"

#include <algorithm>
#include <charconv>
#include <filesystem>
#include <string_view>

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/image_codecs.h"
#include "covoxslam/io/pose_file_readers.h"
#include "covoxslam/io/internal/text_numbers.h"

namespace covox {
namespace io {
namespace {

namespace fs = std::filesystem;

constexpr double kMillimetresPerMetre = 1000.0;
// Kinect-era datasets (7-Scenes, 3DMatch) write 65535 for "no return"; Replica's renders have
// only 0 as invalid (65535 there would be a real 10 m at 6553.5 units per metre).
constexpr uint16_t kKinectInvalidDepth = 65535;

// "frame-000116.depth.png" -> 116 with prefix "frame-" and suffix ".depth.png"; false when
// the name does not have that form.
bool parse_frame_number(const std::string& name, std::string_view prefix, std::string_view suffix,
                        int* number) {
  if (name.size() <= prefix.size() + suffix.size()) return false;
  if (name.compare(0, prefix.size(), prefix) != 0) return false;
  if (name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0) return false;
  const char* begin = name.data() + prefix.size();
  const char* end = name.data() + name.size() - suffix.size();
  return std::from_chars(begin, end, *number).ptr == end && *number >= 0;
}

std::vector<int> list_frames(const fs::path& folder, std::string_view prefix,
                             std::string_view suffix) {
  std::vector<int> numbers;
  std::error_code error;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder, error)) {
    int number = 0;
    if (parse_frame_number(entry.path().filename().string(), prefix, suffix, &number))
      numbers.push_back(number);
  }
  std::sort(numbers.begin(), numbers.end());
  return numbers;
}

// The dataset's zero-padded six-digit frame names.
std::string six_digits(int number) {
  std::string digits = std::to_string(number);
  if (digits.size() < 6) digits.insert(0, 6 - digits.size(), '0');
  return digits;
}

// `name` in `folder` or its parent (3DMatch and nvblox's Replica keep the intrinsics next to
// the sequence folders); empty when in neither.
fs::path find_here_or_parent(const fs::path& folder, const std::string& name) {
  for (const fs::path& candidate : {folder / name, folder.parent_path() / name}) {
    if (fs::is_regular_file(candidate)) return candidate;
  }
  return {};
}

CameraIntrinsics read_camera_matrix_file(const fs::path& file) {
  const std::string path = file.string();
  const std::vector<NumberLine> lines = parse_number_lines(read_text_file(path), path);
  if (lines.size() != 3 || lines[0].values.size() != 3 || lines[1].values.size() != 3 ||
      lines[2].values.size() != 3) {
    throw Error("'" + path + "': expected a 3x3 camera matrix (three rows of three numbers)");
  }
  CameraIntrinsics intrinsics;
  intrinsics.fx = lines[0].values[0];
  intrinsics.cx = lines[0].values[2];
  intrinsics.fy = lines[1].values[1];
  intrinsics.cy = lines[1].values[2];
  return intrinsics;
}

// The number after "key": in a flat JSON object such as Replica's cam_params.json. A real JSON
// parser would be a dependency for five numbers.
double json_number(const std::string& text, const std::string& key, const std::string& path) {
  const std::string quoted = "\"" + key + "\"";
  const size_t key_at = text.find(quoted);
  const size_t colon =
      key_at == std::string::npos ? key_at : text.find(':', key_at + quoted.size());
  if (colon == std::string::npos) throw Error("'" + path + "': no \"" + key + "\" entry");
  const size_t begin = text.find_first_not_of(" \t\r\n", colon + 1);
  const size_t end = begin == std::string::npos ? begin : text.find_first_of(",} \t\r\n", begin);
  double value = 0.0;
  if (begin == std::string::npos ||
      !parse_double(
          std::string_view(text).substr(begin, end == std::string::npos ? end : end - begin),
          &value)) {
    throw Error("'" + path + "': \"" + key + "\" is not a number");
  }
  return value;
}

void check_intrinsics(const CameraIntrinsics& intrinsics, const std::string& source) {
  if (!(intrinsics.fx > 0.0) || !(intrinsics.fy > 0.0) || intrinsics.width <= 0 ||
      intrinsics.height <= 0) {
    throw Error("'" + source + "': invalid intrinsics (fx " + std::to_string(intrinsics.fx) +
                ", fy " + std::to_string(intrinsics.fy) + ", " + std::to_string(intrinsics.width) +
                " x " + std::to_string(intrinsics.height) + " pixels)");
  }
}

}  // namespace

RgbdFolder RgbdFolder::open(const std::string& path) {
  fs::path folder(path);
  // "seq-01/" has an empty file name and "seq-01" as parent: drop the slash so that the
  // parent-folder lookups below see the real parent.
  if (!folder.has_filename() && folder.has_parent_path()) folder = folder.parent_path();
  if (!fs::is_directory(folder))
    throw Error("RGB-D folder '" + path + "' does not exist or is not a folder");

  RgbdFolder result;
  result.path_ = folder.string();
  std::vector<int> seven_scenes = list_frames(folder, "frame-", ".depth.png");
  std::vector<int> replica = list_frames(folder / "results", "depth", ".png");
  if (!seven_scenes.empty()) {
    result.layout_ = RgbdFolderLayout::kSevenScenes;
    result.frame_numbers_ = std::move(seven_scenes);
    result.depth_units_per_m_ = kMillimetresPerMetre;
    const fs::path intrinsics_file = find_here_or_parent(folder, "camera-intrinsics.txt");
    if (intrinsics_file.empty()) {
      throw Error("RGB-D folder '" + path +
                  "': no camera-intrinsics.txt in it or its parent folder");
    }
    result.intrinsics_ = read_camera_matrix_file(intrinsics_file);
    // The intrinsics file has no image size: the first depth image's header gives it.
    const ImageSize size = read_png_size(
        (folder / ("frame-" + six_digits(result.frame_numbers_.front()) + ".depth.png")).string());
    result.intrinsics_.width = size.width;
    result.intrinsics_.height = size.height;
    check_intrinsics(result.intrinsics_, intrinsics_file.string());
  } else if (!replica.empty()) {
    result.layout_ = RgbdFolderLayout::kReplica;
    result.frame_numbers_ = std::move(replica);
    const fs::path parameters_file = find_here_or_parent(folder, "cam_params.json");
    if (parameters_file.empty()) {
      throw Error("RGB-D folder '" + path + "': no cam_params.json in it or its parent folder");
    }
    const std::string parameters_path = parameters_file.string();
    const std::string text = read_text_file(parameters_path);
    result.intrinsics_.fx = json_number(text, "fx", parameters_path);
    result.intrinsics_.fy = json_number(text, "fy", parameters_path);
    result.intrinsics_.cx = json_number(text, "cx", parameters_path);
    result.intrinsics_.cy = json_number(text, "cy", parameters_path);
    result.intrinsics_.width = static_cast<int>(json_number(text, "w", parameters_path));
    result.intrinsics_.height = static_cast<int>(json_number(text, "h", parameters_path));
    result.depth_units_per_m_ = json_number(text, "scale", parameters_path);
    check_intrinsics(result.intrinsics_, parameters_path);
    if (!(result.depth_units_per_m_ > 0.0)) {
      throw Error("'" + parameters_path + "': depth \"scale\" must be positive");
    }
    // One file for the whole sequence: read once here, each frame picks its line.
    result.replica_trajectory_ = read_matrix4_per_line_trajectory((folder / "traj.txt").string());
  } else {
    throw Error("RGB-D folder '" + path +
                "' holds neither 7-Scenes/3DMatch frames (frame-NNNNNN.depth.png) nor " +
                "a Replica sequence (results/depthNNNNNN.png)");
  }
  return result;
}

RgbdFrame RgbdFolder::read_frame(size_t index, ReadStats* stats, bool with_color) const {
  if (index >= frame_numbers_.size()) {
    throw Error("RGB-D folder '" + path_ + "': frame index " + std::to_string(index) +
                " is out of range (" + std::to_string(frame_numbers_.size()) + " frames)");
  }
  const int number = frame_numbers_[index];
  const fs::path folder(path_);
  RgbdFrame frame;
  frame.intrinsics = intrinsics_;
  frame.timestamp_s = number;  // neither layout has times: the frame number orders the frames

  fs::path depth_file;
  fs::path color_file;
  uint16_t invalid_value = 0;
  if (layout_ == RgbdFolderLayout::kSevenScenes) {
    const fs::path stem = folder / ("frame-" + six_digits(number));
    depth_file = stem.string() + ".depth.png";
    color_file = stem.string() + ".color.jpg";
    if (!fs::exists(color_file)) color_file = stem.string() + ".color.png";
    invalid_value = kKinectInvalidDepth;
    frame.T_world_camera = read_matrix4_pose_file(stem.string() + ".pose.txt", stats);
  } else {
    depth_file = folder / "results" / ("depth" + six_digits(number) + ".png");
    color_file = folder / "results" / ("frame" + six_digits(number) + ".jpg");
    if (static_cast<size_t>(number) >= replica_trajectory_.size()) {
      throw Error("'" + (folder / "traj.txt").string() + "' has " +
                  std::to_string(replica_trajectory_.size()) + " poses, frame " +
                  std::to_string(number) + " has none");
    }
    frame.T_world_camera = replica_trajectory_[number];
  }

  const Gray16Image raw = read_png_gray16(depth_file.string());
  if (raw.width != intrinsics_.width || raw.height != intrinsics_.height) {
    throw Error("'" + depth_file.string() + "' is " + std::to_string(raw.width) + " x " +
                std::to_string(raw.height) + " pixels, the intrinsics are for " +
                std::to_string(intrinsics_.width) + " x " + std::to_string(intrinsics_.height));
  }
  frame.depth.width = raw.width;
  frame.depth.height = raw.height;
  frame.depth.depth_m.resize(raw.pixels.size());
  const double metres_per_unit = 1.0 / depth_units_per_m_;
  size_t invalid = 0;
  for (size_t i = 0; i < raw.pixels.size(); ++i) {
    const uint16_t value = raw.pixels[i];
    if (value == 0 || (invalid_value != 0 && value == invalid_value)) {
      frame.depth.depth_m[i] = 0.0f;
      ++invalid;
    } else {
      frame.depth.depth_m[i] = static_cast<float>(value * metres_per_unit);
    }
  }
  if (stats != nullptr) stats->invalid_depth_pixels += invalid;

  if (with_color) {
    if (!fs::exists(color_file)) {
      throw Error("RGB-D folder '" + path_ + "': frame " + std::to_string(number) +
                  " has no colour image ('" + color_file.string() + "')");
    }
    frame.color = read_color_image(color_file.string());
  }
  return frame;
}

}  // namespace io
}  // namespace covox

// Dataset readers of the io layer: raw LiDAR .bin, pose files (with the repair of slightly-off
// rotations and the rejection of impossible ones), PCD in all three encodings, PNG/JPEG images,
// RGB-D folders (7-Scenes, 3DMatch, Replica) and PLY meshes. Real files come from the shared data
// folder (COVOX_DATA_DIR); tests that need it skip with the path when it is missing. Small files
// with known content are written by the tests themselves.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/file_bytes.h"
#include "covoxslam/io/image_codecs.h"
#include "covoxslam/io/lidar_bin_reader.h"
#include "covoxslam/io/internal/lzf_decompress.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/pcd_reader.h"
#include "covoxslam/io/ply_reader.h"
#include "covoxslam/io/pose_file_readers.h"
#include "covoxslam/io/rgbd_folder.h"
#include "covoxslam/io/rigid_pose_check.h"
#include "covoxslam/io/trajectory_io.h"
#include "support/scratch_folder.h"

#if COVOX_HAVE_PNG
#include <png.h>
#endif

namespace covox {
namespace {

namespace fs = std::filesystem;

// The shared-data path of `relative`, or "" after GTEST_SKIP when it is missing.
#define COVOX_DATA_OR_SKIP(variable, relative)                          \
  const std::string variable = io::data_directory() + "/" + (relative); \
  if (!fs::exists(variable)) {                                          \
    GTEST_SKIP() << "shared data not found at '" << variable            \
                 << "' (set COVOX_DATA_DIR to the shared data folder)"; \
  }

#define COVOX_SKIP_WITHOUT_PNG() \
  if (!io::png_reader_available()) GTEST_SKIP() << "built without libpng (install libpng-dev)"

void write_bytes(const std::string& path, const void* data, size_t size) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  file.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  ASSERT_TRUE(file.good()) << path;
}

void write_text(const std::string& path, const std::string& text) {
  write_bytes(path, text.data(), text.size());
}

// Runs `action`, expects a covox::Error whose message contains every one of `parts`.
void expect_error_mentioning(const std::function<void()>& action,
                             const std::vector<std::string>& parts) {
  try {
    action();
    ADD_FAILURE() << "no covox::Error thrown";
  } catch (const Error& error) {
    for (const std::string& part : parts) {
      EXPECT_NE(std::string(error.what()).find(part), std::string::npos)
          << "message '" << error.what() << "' does not mention '" << part << "'";
    }
  }
}

double median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// ---------------------------------------------------------------------------------------------
// Raw LiDAR .bin

TEST(IoLidarBin, KittiScanIsDetectedAsXyzFromItsContent) {
  COVOX_DATA_OR_SKIP(path, "lidar-scans/kitti_00/000000.bin");
  // 1496016 bytes divide by both 12 and 16: only the content can tell the layout.
  ASSERT_EQ(fs::file_size(path) % 48, 0u);
  io::ReadStats stats;
  const io::PointCloud cloud = io::read_lidar_bin(path, io::BinPointLayout::kAutoDetect, &stats);
  EXPECT_EQ(cloud.size(), fs::file_size(path) / 12);
  EXPECT_FALSE(cloud.has_intensities());
  EXPECT_EQ(stats.dropped_non_finite_points, 0u);
  std::vector<double> ranges;
  for (const auto& p : cloud.points_m) ranges.push_back(p.norm());
  const double median_range_m = median(ranges);
  std::printf("kitti_00/000000.bin: %zu points, median range %.2f m\n", cloud.size(),
              median_range_m);
  EXPECT_GT(median_range_m, 3.0);
  EXPECT_LT(median_range_m, 60.0);
  // Forcing the wrong layout gives nonsense (that is what the detection protects against).
  EXPECT_NE(io::read_lidar_bin(path, io::BinPointLayout::kXyzIntensity).size(), cloud.size());
}

TEST(IoLidarBin, NewerCollegeScanAndItsPerPointTimes) {
  COVOX_DATA_OR_SKIP(folder, "lidar-scans/newer_06");
  for (int scan = 0; scan < 3; ++scan) {
    const std::string id = "0" + std::to_string(scan);
    const io::PointCloud raw = io::read_lidar_bin(folder + "/raw_" + id + ".bin");
    const io::PointCloud deskewed = io::read_lidar_bin(folder + "/deskewed_" + id + ".bin");
    const std::vector<float> times_s = io::read_float32_file(folder + "/times_" + id + ".bin");
    EXPECT_GT(raw.size(), 10000u);
    EXPECT_EQ(raw.size(), deskewed.size());
    EXPECT_EQ(times_s.size(), raw.size());
    const auto [earliest, latest] = std::minmax_element(times_s.begin(), times_s.end());
    EXPECT_GE(*earliest, 0.0f);
    EXPECT_LE(*latest, 0.11f);  // one 10 Hz sweep
  }
}

TEST(IoLidarBin, KeyframeDumpWithGraphPoses) {
  COVOX_DATA_OR_SKIP(folder, "lidar-scans/kitti_07_dump");
  io::ReadStats stats;
  const auto keyframes = io::read_keyframe_graph_file(folder + "/graph.txt", &stats);
  ASSERT_EQ(keyframes.size(), 5u);
  for (size_t k = 0; k < keyframes.size(); ++k) {
    EXPECT_EQ(keyframes[k].id, static_cast<int>(k));
    const io::PointCloud cloud =
        io::read_lidar_bin(folder + "/00000" + std::to_string(k) + "/points.bin");
    EXPECT_GT(cloud.size(), 15000u);
    EXPECT_LT(cloud.size(), 30000u);
    if (k > 0) {
      const double step_m = (keyframes[k].T_world_sensor.translation() -
                             keyframes[k - 1].T_world_sensor.translation())
                                .norm();
      EXPECT_GT(step_m, 2.0);  // README: keyframes 3-12 m apart
      EXPECT_LT(step_m, 13.0);
    }
  }
}

TEST(IoLidarBin, WrittenScanWithIntensityDropsNonFinitePoints) {
  ScratchFolder scratch;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<float> values = {1, 2,  3, 10, 4, 5,   6, 20, nan, 0,
                                     0, 30, 7, 8,  9, nan, 1, 1,  1,   40};
  const std::string path = scratch.file("scan.bin");
  write_bytes(path, values.data(), values.size() * sizeof(float));
  io::ReadStats stats;
  const io::PointCloud cloud = io::read_lidar_bin(path, io::BinPointLayout::kXyzIntensity, &stats);
  ASSERT_EQ(cloud.size(), 3u);
  EXPECT_EQ(stats.dropped_non_finite_points, 2u);
  EXPECT_EQ(cloud.intensities, (std::vector<float>{10, 20, 40}));
  EXPECT_EQ(cloud.points_m[1], Eigen::Vector3f(4, 5, 6));

  write_bytes(path, values.data(), 10);  // not a whole float
  expect_error_mentioning([&] { io::read_lidar_bin(path); }, {path, "truncated"});
  expect_error_mentioning([&] { io::read_lidar_bin(scratch.file("missing.bin")); },
                          {"missing.bin"});
}

// ---------------------------------------------------------------------------------------------
// Pose files

// Frames of a 7-Scenes folder, counted from its pose files (the shared data has 300; the subset
// carried to the GPU machine fewer), so the tests check the reader against the folder itself.
int count_seven_scenes_frames(const std::string& folder) {
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    const std::string name = entry.path().filename().string();
    if (name.size() > 9 && name.compare(name.size() - 9, 9, ".pose.txt") == 0) ++count;
  }
  return count;
}

TEST(IoPoseFiles, SevenScenesRotationsAreReorthonormalisedAndCounted) {
  COVOX_DATA_OR_SKIP(folder, "7scenes-redkitchen");
  io::ReadStats stats;
  double worst_input_error = 0.0;
  const int frames = count_seven_scenes_frames(folder);
  ASSERT_GT(frames, 0);
  for (int frame = 0; frame < frames; ++frame) {
    char name[64];
    std::snprintf(name, sizeof(name), "/frame-%06d.pose.txt", frame);
    const auto pose = io::read_matrix4_pose_file(folder + name, &stats);
    EXPECT_LT(io::orthonormality_error(pose.linear()), 1e-12);
    EXPECT_GT(pose.linear().determinant(), 0.0);
    // What the file said: read again with an "accept anything" repair threshold.
    io::PoseTolerances keep_as_is;
    keep_as_is.reorthonormalize_above_error = 1.0;
    worst_input_error =
        std::max(worst_input_error,
                 io::orthonormality_error(
                     io::read_matrix4_pose_file(folder + name, nullptr, keep_as_is).linear()));
  }
  std::printf("7-Scenes: %zu of %d poses re-orthonormalised, worst |R^T R - I| in the files %.2e\n",
              stats.reorthonormalized_poses, frames, worst_input_error);
  EXPECT_GT(stats.reorthonormalized_poses, 0u);
  EXPECT_GT(worst_input_error, 1e-4);
}

TEST(IoPoseFiles, KittiMatrixAndReplicaTrajectories) {
  COVOX_DATA_OR_SKIP(mulran, "mulran-riverside02");
  COVOX_DATA_OR_SKIP(replica, "nvblox-testdata/replica/office0/traj.txt");
  io::ReadStats stats;
  const auto odometry = io::read_kitti_pose_file(mulran + "/odom_poses.txt", &stats);
  const auto optimized = io::read_kitti_pose_file(mulran + "/optimized_poses.txt", &stats);
  EXPECT_EQ(odometry.size(), 281u);
  EXPECT_EQ(optimized.size(), 281u);
  double path_length_m = 0.0;
  for (size_t i = 1; i < optimized.size(); ++i) {
    path_length_m += (optimized[i].translation() - optimized[i - 1].translation()).norm();
  }
  std::printf("MulRan optimized path %.0f m; Replica/MulRan poses repaired: %zu\n", path_length_m,
              stats.reorthonormalized_poses);
  EXPECT_GT(path_length_m, 1500.0);  // README: 2.4 km
  const auto trajectory = io::read_matrix4_per_line_trajectory(replica, &stats);
  EXPECT_EQ(trajectory.size(), 2000u);
}

TEST(IoPoseFiles, RejectsNonFiniteAndDegeneratePosesNamingTheFile) {
  ScratchFolder scratch;
  const std::string bad_value = scratch.file("nan.pose.txt");
  write_text(bad_value, "1 0 0 0\n0 nan 0 0\n0 0 1 0\n0 0 0 1\n");
  expect_error_mentioning([&] { io::read_matrix4_pose_file(bad_value); },
                          {bad_value, "non-finite"});

  const std::string degenerate = scratch.file("zero.pose.txt");
  write_text(degenerate, "0 0 0 1\n0 0 0 2\n0 0 0 3\n0 0 0 1\n");
  expect_error_mentioning([&] { io::read_matrix4_pose_file(degenerate); },
                          {degenerate, "determinant"});

  const std::string reflection = scratch.file("mirror.txt");
  write_text(reflection, "1 0 0 0 0 1 0 0 0 0 -1 0\n");
  expect_error_mentioning([&] { io::read_kitti_pose_file(reflection); },
                          {reflection + ":1", "reflection"});

  const std::string scaled = scratch.file("scaled.txt");
  write_text(scaled, "# comment\n1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 2 0 0 0 0 2 0\n");
  expect_error_mentioning([&] { io::read_kitti_pose_file(scaled); },
                          {scaled + ":3", "orthonormal"});

  const std::string short_line = scratch.file("short.txt");
  write_text(short_line, "1 0 0 0 0 1 0 0 0 0 1\n");
  expect_error_mentioning([&] { io::read_kitti_pose_file(short_line); }, {short_line + ":1", "12"});

  const std::string zero_quaternion = scratch.file("graph.txt");
  write_text(zero_quaternion, "v0 1 2 3 0 0 0 0\n");
  expect_error_mentioning([&] { io::read_keyframe_graph_file(zero_quaternion); },
                          {zero_quaternion + ":1", "quaternion"});

  // Slightly off (as printed by a drifting odometry): repaired and counted, not rejected.
  const std::string slightly_off = scratch.file("slightly_off.txt");
  write_text(slightly_off, "1.0002 0 0 0 0 1 0 0 0 0 1 0\n");
  io::ReadStats stats;
  const auto poses = io::read_kitti_pose_file(slightly_off, &stats);
  EXPECT_EQ(stats.reorthonormalized_poses, 1u);
  EXPECT_LT(io::orthonormality_error(poses.at(0).linear()), 1e-12);
}

// ---------------------------------------------------------------------------------------------
// LZF and PCD

// A small LZF compressor for writing binary_compressed test files (greedy, one hash slot per
// 3-byte prefix). It emits both literal runs and back references, including overlapping ones,
// so files written with it exercise every path of the decoder.
std::vector<uint8_t> lzf_compress_for_test(const std::vector<uint8_t>& input) {
  constexpr size_t kMaxOffset = 8192, kMaxLength = 264, kMaxLiteral = 32;
  std::vector<uint8_t> out;
  std::vector<int64_t> last_seen(1 << 16, -1);
  size_t literal_start = 0;
  auto flush_literals = [&](size_t end) {
    while (literal_start < end) {
      const size_t run = std::min(kMaxLiteral, end - literal_start);
      out.push_back(static_cast<uint8_t>(run - 1));
      out.insert(out.end(), input.begin() + literal_start, input.begin() + literal_start + run);
      literal_start += run;
    }
  };
  size_t i = 0;
  while (i + 2 < input.size()) {
    const uint32_t key =
        (uint32_t(input[i]) << 8 ^ uint32_t(input[i + 1]) << 4 ^ input[i + 2]) & 0xffff;
    const int64_t candidate = last_seen[key];
    last_seen[key] = static_cast<int64_t>(i);
    if (candidate >= 0 && i - candidate <= kMaxOffset &&
        std::memcmp(&input[candidate], &input[i], 3) == 0) {
      size_t length = 3;
      while (length < kMaxLength && i + length < input.size() &&
             input[candidate + length] == input[i + length]) {
        ++length;
      }
      flush_literals(i);
      const size_t offset = i - candidate - 1, stored = length - 2;
      if (stored < 7) {
        out.push_back(static_cast<uint8_t>(stored << 5 | offset >> 8));
      } else {
        out.push_back(static_cast<uint8_t>(7 << 5 | offset >> 8));
        out.push_back(static_cast<uint8_t>(stored - 7));
      }
      out.push_back(static_cast<uint8_t>(offset & 0xff));
      i += length;
      literal_start = i;
    } else {
      ++i;
    }
  }
  flush_literals(input.size());
  return out;
}

TEST(IoLzf, DecodesLiteralsAndOverlappingReferencesAndRejectsCorruptStreams) {
  // "ab" literal, then a reference of length 7 at distance 2: "ab" repeated -> "ababababa".
  const std::vector<uint8_t> stream = {1, 'a', 'b', (7 - 2) << 5, 1};
  std::vector<uint8_t> out(9);
  io::lzf_decompress(stream.data(), stream.size(), out.data(), out.size(), "test");
  EXPECT_EQ(std::string(out.begin(), out.end()), "ababababa");

  std::vector<uint8_t> original(5000);
  for (size_t i = 0; i < original.size(); ++i)
    original[i] = static_cast<uint8_t>((i * i / 7) % 13 + (i % 3));
  const std::vector<uint8_t> compressed = lzf_compress_for_test(original);
  EXPECT_LT(compressed.size(), original.size());
  std::vector<uint8_t> decoded(original.size());
  io::lzf_decompress(compressed.data(), compressed.size(), decoded.data(), decoded.size(), "test");
  EXPECT_EQ(decoded, original);

  const std::vector<uint8_t> before_start = {0, 'a', 1 << 5, 5};  // distance 6 after 1 byte
  expect_error_mentioning(
      [&] { io::lzf_decompress(before_start.data(), before_start.size(), out.data(), 9, "ctx"); },
      {"ctx", "before the start"});
  expect_error_mentioning([&] { io::lzf_decompress(stream.data(), 2, out.data(), 9, "ctx"); },
                          {"ctx", "past the end"});
  expect_error_mentioning(
      [&] { io::lzf_decompress(stream.data(), stream.size(), out.data(), 8, "ctx"); }, {"ctx"});
  expect_error_mentioning([&] { io::lzf_decompress(stream.data(), 3, out.data(), 9, "ctx"); },
                          {"ctx", "expected 9"});
}

void expect_same_cloud(const io::PointCloud& a, const io::PointCloud& b) {
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(a.points_m, b.points_m);
  EXPECT_EQ(a.intensities, b.intensities);
  EXPECT_EQ(a.colors, b.colors);
}

TEST(IoPcd, MulranScanIsBinaryWithIntensity) {
  COVOX_DATA_OR_SKIP(folder, "mulran-riverside02/Scans");
  io::ReadStats stats;
  size_t total = 0;
  for (const char* name : {"000000.pcd", "000140.pcd", "000280.pcd"}) {
    const io::PointCloud cloud = io::read_pcd(folder + "/" + name, &stats);
    EXPECT_GT(cloud.size(), 5000u) << name;  // README: ~13k after downsampling, fewer in open areas
    ASSERT_EQ(cloud.intensities.size(), cloud.size());
    EXPECT_FALSE(cloud.has_colors());
    for (const auto& p : cloud.points_m) ASSERT_LT(p.norm(), 300.0f) << name;
    total += cloud.size();
  }
  std::printf("MulRan: %zu points in 3 scans, %zu dropped as non-finite\n", total,
              stats.dropped_non_finite_points);
}

TEST(IoPcd, PclRoomScanIsBinaryCompressed) {
  COVOX_DATA_OR_SKIP(path, "pcl-room/room_scan1.pcd");
  io::ReadStats stats;
  const io::PointCloud cloud = io::read_pcd(path, &stats);
  EXPECT_EQ(cloud.size() + stats.dropped_non_finite_points, 112586u);
  EXPECT_GT(cloud.size(), 100000u);
  Eigen::AlignedBox3f bounds;
  for (const auto& p : cloud.points_m) bounds.extend(p);
  const Eigen::Vector3f extent_m = bounds.sizes();
  std::printf("pcl-room scan 1: %zu points (%zu dropped), extent %.2f x %.2f x %.2f m\n",
              cloud.size(), stats.dropped_non_finite_points, extent_m.x(), extent_m.y(),
              extent_m.z());
  EXPECT_GT(extent_m.maxCoeff(), 2.0f);  // a room, not a degenerate decode
  EXPECT_LT(extent_m.maxCoeff(), 50.0f);

  // Cut it short and flip a byte in the middle of the compressed data: both must fail clearly.
  ScratchFolder scratch;
  std::vector<uint8_t> bytes = io::read_file_bytes(path);
  const std::string truncated = scratch.file("truncated.pcd");
  write_bytes(truncated, bytes.data(), bytes.size() / 2);
  expect_error_mentioning([&] { io::read_pcd(truncated); }, {truncated, "truncated"});
  const std::string corrupt = scratch.file("corrupt.pcd");
  const size_t data_start =
      std::string(bytes.begin(), bytes.begin() + 1024).find("binary_compressed\n") + 18;
  bytes[data_start + 4] ^= 0x40;  // the uncompressed size
  write_bytes(corrupt, bytes.data(), bytes.size());
  expect_error_mentioning([&] { io::read_pcd(corrupt); }, {corrupt, "corrupt"});
}

// A cloud to write in all encodings: fields in an unusual order and of mixed types, padding,
// packed colour, and one point with a NaN coordinate.
struct TestCloudFile {
  static constexpr int kPoints = 200;
  std::string header_fields =
      "FIELDS rgb _ z x intensity y\nSIZE 4 1 8 4 2 4\nTYPE F U F F U I\nCOUNT 1 3 1 1 1 1\n";
  std::vector<uint32_t> rgb;
  std::vector<double> z;
  std::vector<float> x;
  std::vector<uint16_t> intensity;
  std::vector<int32_t> y;

  TestCloudFile() {
    for (int i = 0; i < kPoints; ++i) {
      rgb.push_back(
          static_cast<uint32_t>((i * 37 % 256) << 16 | (i * 11 % 256) << 8 | (255 - i % 256)));
      z.push_back(0.25 * (i % 17) - 1.0 + 1e-9 * i);
      x.push_back(i == 57 ? std::numeric_limits<float>::quiet_NaN() : 0.1f * i);
      intensity.push_back(static_cast<uint16_t>(i * 300));
      y.push_back(i % 5 - 2);
    }
  }

  std::string header(const char* encoding) const {
    return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n" + header_fields + "WIDTH " +
           std::to_string(kPoints) + "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
           std::to_string(kPoints) + "\nDATA " + encoding + "\n";
  }

  std::string ascii() const {
    std::string text = header("ascii");
    char line[256];
    for (int i = 0; i < kPoints; ++i) {
      // rgb as PCL writes it (the uint32 of the packed bits) on even points, as the float with
      // those bits on odd points (other writers); both must decode to the same colour.
      float rgb_as_float;
      std::memcpy(&rgb_as_float, &rgb[i], 4);
      const std::string rgb_text = i % 2 == 0 ? std::to_string(rgb[i]) : [&] {
        char buffer[64];
        std::snprintf(buffer, sizeof(buffer), "%.9g", rgb_as_float);
        return std::string(buffer);
      }();
      std::snprintf(line, sizeof(line), "%s 0 0 0 %.17g %.9g %u %d\n", rgb_text.c_str(), z[i], x[i],
                    unsigned(intensity[i]), int(y[i]));
      text += line;
    }
    return text;
  }

  // Field-major (true) or point-major data bytes.
  std::vector<uint8_t> data(bool field_major) const {
    std::vector<uint8_t> bytes;
    auto append = [&](const void* value, size_t size) {
      const auto* begin = static_cast<const uint8_t*>(value);
      bytes.insert(bytes.end(), begin, begin + size);
    };
    const uint8_t padding[3] = {0xaa, 0xbb, 0xcc};
    auto append_field = [&](int field, int i) {
      switch (field) {
        case 0:
          append(&rgb[i], 4);
          break;
        case 1:
          append(padding, 3);
          break;
        case 2:
          append(&z[i], 8);
          break;
        case 3:
          append(&x[i], 4);
          break;
        case 4:
          append(&intensity[i], 2);
          break;
        default:
          append(&y[i], 4);
          break;
      }
    };
    if (field_major) {
      for (int field = 0; field < 6; ++field) {
        for (int i = 0; i < kPoints; ++i) append_field(field, i);
      }
    } else {
      for (int i = 0; i < kPoints; ++i) {
        for (int field = 0; field < 6; ++field) append_field(field, i);
      }
    }
    return bytes;
  }

  std::vector<uint8_t> binary() const {
    const std::string text = header("binary");
    std::vector<uint8_t> bytes(text.begin(), text.end());
    const std::vector<uint8_t> points = data(false);
    bytes.insert(bytes.end(), points.begin(), points.end());
    return bytes;
  }

  std::vector<uint8_t> binary_compressed() const {
    const std::string text = header("binary_compressed");
    std::vector<uint8_t> bytes(text.begin(), text.end());
    const std::vector<uint8_t> raw = data(true);
    const std::vector<uint8_t> compressed = lzf_compress_for_test(raw);
    const uint32_t sizes[2] = {static_cast<uint32_t>(compressed.size()),
                               static_cast<uint32_t>(raw.size())};
    const auto* size_bytes = reinterpret_cast<const uint8_t*>(sizes);
    bytes.insert(bytes.end(), size_bytes, size_bytes + sizeof(sizes));
    bytes.insert(bytes.end(), compressed.begin(), compressed.end());
    return bytes;
  }
};

TEST(IoPcd, SameCloudInAllThreeEncodingsReadsIdentically) {
  ScratchFolder scratch;
  const TestCloudFile source;
  const std::string ascii = scratch.file("cloud_ascii.pcd"),
                    binary = scratch.file("cloud_binary.pcd"),
                    compressed = scratch.file("cloud_compressed.pcd");
  write_text(ascii, source.ascii());
  const std::vector<uint8_t> binary_bytes = source.binary(),
                             compressed_bytes = source.binary_compressed();
  write_bytes(binary, binary_bytes.data(), binary_bytes.size());
  write_bytes(compressed, compressed_bytes.data(), compressed_bytes.size());

  io::ReadStats ascii_stats, binary_stats, compressed_stats;
  const io::PointCloud from_ascii = io::read_pcd(ascii, &ascii_stats);
  const io::PointCloud from_binary = io::read_pcd(binary, &binary_stats);
  const io::PointCloud from_compressed = io::read_pcd(compressed, &compressed_stats);
  EXPECT_EQ(ascii_stats.dropped_non_finite_points, 1u);
  EXPECT_EQ(binary_stats.dropped_non_finite_points, 1u);
  EXPECT_EQ(compressed_stats.dropped_non_finite_points, 1u);
  ASSERT_EQ(from_binary.size(), size_t(TestCloudFile::kPoints - 1));
  expect_same_cloud(from_ascii, from_binary);
  expect_same_cloud(from_compressed, from_binary);

  // Spot-check conversions against the source values (point 58 is the 58th kept: 57 was NaN).
  const int i = 58;
  EXPECT_EQ(from_binary.points_m[57],
            Eigen::Vector3f(source.x[i], float(source.y[i]), float(source.z[i])));
  EXPECT_EQ(from_binary.intensities[57], float(source.intensity[i]));
  const std::array<uint8_t, 3> expected_color = {
      uint8_t(source.rgb[i] >> 16), uint8_t(source.rgb[i] >> 8), uint8_t(source.rgb[i])};
  EXPECT_EQ(from_binary.colors[57], expected_color);
}

TEST(IoPcd, BrokenFilesFailNamingTheFile) {
  ScratchFolder scratch;
  const TestCloudFile source;
  const std::string path = scratch.file("broken.pcd");

  std::vector<uint8_t> bytes = source.binary();
  write_bytes(path, bytes.data(), bytes.size() - 7);
  expect_error_mentioning([&] { io::read_pcd(path); }, {path, "truncated"});

  bytes = source.binary_compressed();
  bytes.back() ^= 0xff;  // the last literal byte or reference offset
  bytes.resize(bytes.size() - 3);
  write_bytes(path, bytes.data(), bytes.size());
  expect_error_mentioning([&] { io::read_pcd(path); }, {path});

  std::string text = source.ascii();
  write_text(path, text.substr(0, text.size() / 2));
  expect_error_mentioning([&] { io::read_pcd(path); }, {path});
  write_text(path, source.header("ascii") + "1 0 0 0 2 3 4\n");  // 8 tokens per point, 7 given
  expect_error_mentioning([&] { io::read_pcd(path); }, {path + ":12", "8 values per point"});

  write_text(
      path,
      "VERSION 0.7\nFIELDS normal_x normal_y\nSIZE 4 4\nTYPE F F\nWIDTH 0\nPOINTS 0\nDATA ascii\n");
  expect_error_mentioning([&] { io::read_pcd(path); }, {path, "x, y and z"});
  write_text(path,
             "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA lzma\n");
  expect_error_mentioning([&] { io::read_pcd(path); }, {path, "lzma"});
}

// ---------------------------------------------------------------------------------------------
// Images

#if COVOX_HAVE_PNG
// Writes with libpng's simplified API; 16-bit grey is written as the values given.
void write_png(const std::string& path, int width, int height, uint32_t format,
               const void* pixels) {
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  image.width = width;
  image.height = height;
  image.format = format;
  ASSERT_TRUE(png_image_write_to_file(&image, path.c_str(), 0, pixels, 0, nullptr))
      << image.message;
}
#endif

TEST(IoImages, SevenScenesDepthAndColour) {
  COVOX_SKIP_WITHOUT_PNG();
  COVOX_DATA_OR_SKIP(folder, "7scenes-redkitchen");
  const io::Gray16Image depth = io::read_png_gray16(folder + "/frame-000000.depth.png");
  ASSERT_EQ(depth.width, 640);
  ASSERT_EQ(depth.height, 480);
  std::vector<double> valid_mm;
  for (uint16_t value : depth.pixels) {
    if (value != 0 && value != 65535) valid_mm.push_back(value);
  }
  EXPECT_GT(valid_mm.size(), depth.pixels.size() / 2);
  const double median_mm = median(valid_mm);
  std::printf("7-Scenes frame 0: %zu valid depth pixels, median %.0f mm\n", valid_mm.size(),
              median_mm);
  EXPECT_GT(median_mm, 400.0);  // an indoor Kinect scene: metres, not bytes swapped
  EXPECT_LT(median_mm, 5000.0);

  const io::ImageSize size = io::read_png_size(folder + "/frame-000000.depth.png");
  EXPECT_EQ(size.width, 640);
  EXPECT_EQ(size.height, 480);

  if (!io::jpeg_reader_available()) GTEST_SKIP() << "built without libjpeg (install libjpeg-dev)";
  const io::ColorImage color = io::read_color_image(folder + "/frame-000000.color.jpg");
  EXPECT_EQ(color.width, 640);
  EXPECT_EQ(color.height, 480);
  ASSERT_EQ(color.rgb.size(), 640u * 480u * 3u);
  double mean = 0.0;
  for (uint8_t value : color.rgb) mean += value;
  mean /= color.rgb.size();
  EXPECT_GT(mean, 20.0);
  EXPECT_LT(mean, 235.0);

  // A cut-off JPEG is an error, not an image with grey rows.
  ScratchFolder scratch;
  const std::vector<uint8_t> bytes = io::read_file_bytes(folder + "/frame-000000.color.jpg");
  const std::string truncated = scratch.file("cut.jpg");
  write_bytes(truncated, bytes.data(), bytes.size() / 2);
  expect_error_mentioning([&] { io::read_color_image(truncated); }, {truncated, "truncated"});
}

TEST(IoImages, WrittenPngsRoundTrip) {
  COVOX_SKIP_WITHOUT_PNG();
#if COVOX_HAVE_PNG
  ScratchFolder scratch;
  const int width = 7, height = 5;
  std::vector<uint16_t> depth(width * height);
  for (size_t i = 0; i < depth.size(); ++i) depth[i] = static_cast<uint16_t>(i * 1871 + 258);
  depth[0] = 0;
  depth[1] = 65535;
  const std::string depth_path = scratch.file("depth.png");
  write_png(depth_path, width, height, PNG_FORMAT_LINEAR_Y, depth.data());
  const io::Gray16Image read_depth = io::read_png_gray16(depth_path);
  EXPECT_EQ(read_depth.width, width);
  EXPECT_EQ(read_depth.height, height);
  EXPECT_EQ(read_depth.pixels, depth);  // byte order right (258 = 0x0102)

  std::vector<uint8_t> rgb(width * height * 3);
  for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = static_cast<uint8_t>(i * 13);
  const std::string rgb_path = scratch.file("rgb.png");
  write_png(rgb_path, width, height, PNG_FORMAT_RGB, rgb.data());
  const io::ColorImage read_rgb = io::read_color_image(rgb_path);
  EXPECT_EQ(read_rgb.width, width);
  EXPECT_EQ(read_rgb.rgb, rgb);

  // 8-bit grey is expanded to RGB for colour, but refused as depth.
  std::vector<uint8_t> grey(width * height);
  for (size_t i = 0; i < grey.size(); ++i) grey[i] = static_cast<uint8_t>(i * 5);
  const std::string grey_path = scratch.file("grey.png");
  write_png(grey_path, width, height, PNG_FORMAT_GRAY, grey.data());
  const io::ColorImage grey_as_rgb = io::read_color_image(grey_path);
  ASSERT_EQ(grey_as_rgb.rgb.size(), grey.size() * 3);
  EXPECT_EQ(grey_as_rgb.at(2, 3), (std::array<uint8_t, 3>{grey[17], grey[17], grey[17]}));
  expect_error_mentioning([&] { io::read_png_gray16(grey_path); },
                          {grey_path, "8-bit grey", "16-bit grey"});

  const std::vector<uint8_t> bytes = io::read_file_bytes(depth_path);
  const std::string truncated = scratch.file("cut.png");
  write_bytes(truncated, bytes.data(), bytes.size() - 20);
  expect_error_mentioning([&] { io::read_png_gray16(truncated); }, {truncated});
  const std::string text = scratch.file("not_an_image.png");
  write_text(text, "hello, I am text");
  expect_error_mentioning([&] { io::read_png_gray16(text); }, {text, "not a PNG"});
  expect_error_mentioning([&] { io::read_color_image(text); }, {text, "neither a PNG nor a JPEG"});
#endif
}

TEST(IoImages, MissingCodecOrCorruptDataIsNamed) {
  ScratchFolder scratch;
  // A PNG signature followed by garbage: a corrupt PNG with libpng, a missing-library error
  // naming libpng without it. Either way the file is named.
  const std::string path = scratch.file("garbage.png");
  const uint8_t bytes[16] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 1, 2, 3, 4, 5, 6, 7, 8};
  write_bytes(path, bytes, sizeof(bytes));
  if (io::png_reader_available()) {
    expect_error_mentioning([&] { io::read_png_gray16(path); }, {path, "corrupt PNG"});
  } else {
    EXPECT_THROW(io::read_png_gray16(path), NotAvailableError);
    expect_error_mentioning([&] { io::read_png_gray16(path); }, {path, "libpng"});
  }
  const std::string jpeg_path = scratch.file("garbage.jpg");
  const uint8_t jpeg_bytes[8] = {0xff, 0xd8, 0xff, 0xe0, 0, 0, 0, 0};
  write_bytes(jpeg_path, jpeg_bytes, sizeof(jpeg_bytes));
  expect_error_mentioning([&] { io::read_color_image(jpeg_path); },
                          {jpeg_path, io::jpeg_reader_available() ? "JPEG" : "libjpeg"});
}

// ---------------------------------------------------------------------------------------------
// RGB-D folders

TEST(IoRgbdFolder, SevenScenes) {
  COVOX_SKIP_WITHOUT_PNG();
  COVOX_DATA_OR_SKIP(folder, "7scenes-redkitchen");
  const io::RgbdFolder rgbd = io::RgbdFolder::open(folder);
  EXPECT_EQ(rgbd.layout(), io::RgbdFolderLayout::kSevenScenes);
  const size_t frames = static_cast<size_t>(count_seven_scenes_frames(folder));
  ASSERT_GE(frames, 2u);
  ASSERT_EQ(rgbd.size(), frames);
  EXPECT_EQ(rgbd.frame_numbers().back(), static_cast<int>(frames) - 1);
  EXPECT_EQ(rgbd.intrinsics().fx, 585.0);
  EXPECT_EQ(rgbd.intrinsics().fy, 585.0);
  EXPECT_EQ(rgbd.intrinsics().cx, 320.0);
  EXPECT_EQ(rgbd.intrinsics().cy, 240.0);
  EXPECT_EQ(rgbd.intrinsics().width, 640);
  EXPECT_EQ(rgbd.intrinsics().height, 480);
  EXPECT_EQ(rgbd.depth_units_per_m(), 1000.0);

  io::ReadStats stats;
  for (size_t index : {size_t(0), frames / 2, frames - 1}) {
    const io::RgbdFrame frame = rgbd.read_frame(index, &stats, io::jpeg_reader_available());
    EXPECT_EQ(frame.timestamp_s, double(rgbd.frame_numbers()[index]));
    EXPECT_EQ(frame.depth.width, 640);
    size_t valid = 0;
    for (float depth_m : frame.depth.depth_m) {
      ASSERT_TRUE(depth_m == 0.0f || (depth_m > 0.2f && depth_m < 10.0f)) << depth_m;
      valid += depth_m > 0.0f;
    }
    EXPECT_GT(valid, frame.depth.depth_m.size() / 2);
    EXPECT_LT(io::orthonormality_error(frame.T_world_camera.linear()), 1e-12);
    if (io::jpeg_reader_available()) {
      EXPECT_EQ(frame.color.width, 640);
    }
  }
  EXPECT_GT(stats.invalid_depth_pixels, 0u);
  EXPECT_GT(stats.reorthonormalized_poses, 0u);
  const io::RgbdFrame without_color = rgbd.read_frame(1, nullptr, false);
  EXPECT_TRUE(without_color.color.empty());
  expect_error_mentioning([&] { rgbd.read_frame(frames); }, {folder, "out of range"});
}

TEST(IoRgbdFolder, ThreeDMatchWithIntrinsicsInTheParentFolder) {
  COVOX_SKIP_WITHOUT_PNG();
  COVOX_DATA_OR_SKIP(folder, "nvblox-testdata/3dmatch/seq-01");
  const io::RgbdFolder rgbd = io::RgbdFolder::open(folder);
  EXPECT_EQ(rgbd.frame_numbers(), (std::vector<int>{0, 1, 2, 116, 422}));
  EXPECT_NEAR(rgbd.intrinsics().fx, 570.342205, 1e-9);
  EXPECT_EQ(rgbd.intrinsics().cx, 320.0);
  EXPECT_EQ(rgbd.intrinsics().width, 640);
  const io::RgbdFrame frame = rgbd.read_frame(3);
  EXPECT_EQ(frame.timestamp_s, 116.0);
  EXPECT_EQ(frame.color.width, frame.depth.width);
  EXPECT_EQ(frame.color.height, frame.depth.height);
  // Frame 116 is far along the sequence: the camera has moved away from frame 0.
  EXPECT_GT((frame.T_world_camera.translation() -
             rgbd.read_frame(0, nullptr, false).T_world_camera.translation())
                .norm(),
            0.05);
}

TEST(IoRgbdFolder, ReplicaWithTrajectoryAndDepthScale) {
  COVOX_SKIP_WITHOUT_PNG();
  COVOX_DATA_OR_SKIP(folder, "nvblox-testdata/replica/office0");
  const io::RgbdFolder rgbd = io::RgbdFolder::open(folder);
  EXPECT_EQ(rgbd.layout(), io::RgbdFolderLayout::kReplica);
  ASSERT_EQ(rgbd.size(), 4u);
  EXPECT_EQ(rgbd.intrinsics().fx, 600.0);
  EXPECT_EQ(rgbd.intrinsics().cx, 599.5);
  EXPECT_EQ(rgbd.intrinsics().cy, 339.5);
  EXPECT_EQ(rgbd.intrinsics().width, 1200);
  EXPECT_EQ(rgbd.intrinsics().height, 680);
  EXPECT_EQ(rgbd.depth_units_per_m(), 6553.5);
  const auto trajectory = io::read_matrix4_per_line_trajectory(folder + "/traj.txt");
  for (size_t index = 0; index < rgbd.size(); ++index) {
    const io::RgbdFrame frame = rgbd.read_frame(index, nullptr, io::jpeg_reader_available());
    EXPECT_TRUE(frame.T_world_camera.isApprox(trajectory[rgbd.frame_numbers()[index]], 1e-12));
    std::vector<double> valid_m;
    for (float depth_m : frame.depth.depth_m) {
      if (depth_m > 0.0f) valid_m.push_back(depth_m);
    }
    EXPECT_GT(valid_m.size(), frame.depth.depth_m.size() * 9 / 10);  // a render: nearly all valid
    const double median_m = median(valid_m);
    EXPECT_GT(median_m, 0.5);  // an office seen from inside
    EXPECT_LT(median_m, 6.0);
    if (io::jpeg_reader_available()) {
      EXPECT_EQ(frame.color.width, 1200);
    }
  }
}

TEST(IoRgbdFolder, MissingFilesFailNamingThem) {
  ScratchFolder scratch;
  expect_error_mentioning([&] { io::RgbdFolder::open(scratch.path().string()); },
                          {scratch.path().string(), "neither"});
  expect_error_mentioning([&] { io::RgbdFolder::open(scratch.file("nope")); },
                          {"nope", "does not exist"});
#if COVOX_HAVE_PNG
  const std::vector<uint16_t> depth(4 * 3, 1000);
  write_png(scratch.file("frame-000007.depth.png"), 4, 3, PNG_FORMAT_LINEAR_Y, depth.data());
  expect_error_mentioning([&] { io::RgbdFolder::open(scratch.path().string()); },
                          {"camera-intrinsics.txt"});
  write_text(scratch.file("camera-intrinsics.txt"), "500 0 2\n0 500 1.5\n0 0 1\n");
  const io::RgbdFolder rgbd = io::RgbdFolder::open(scratch.path().string());
  ASSERT_EQ(rgbd.size(), 1u);
  EXPECT_EQ(rgbd.intrinsics().width, 4);
  expect_error_mentioning([&] { rgbd.read_frame(0); }, {"frame-000007.pose.txt"});
  write_text(scratch.file("frame-000007.pose.txt"), "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  expect_error_mentioning([&] { rgbd.read_frame(0); },
                          {"frame-000007.color.png", "no colour image"});
  io::ReadStats stats;
  const io::RgbdFrame frame = rgbd.read_frame(0, &stats, false);
  EXPECT_EQ(frame.depth.depth_m, std::vector<float>(12, 1.0f));
  EXPECT_EQ(stats.invalid_depth_pixels, 0u);
#endif
}

// ---------------------------------------------------------------------------------------------
// PLY meshes

TEST(IoPly, WriterOutputReadsBackExactly) {
  ScratchFolder scratch;
  map::Mesh mesh;
  for (int i = 0; i < 30; ++i) {
    mesh.vertices_m.push_back(Vec3f(0.1f * i, std::sin(0.3f * i), -1.5f + 0.01f * i));
    mesh.colors.push_back(Rgb8{uint8_t(i * 8), uint8_t(255 - i), uint8_t(i)});
  }
  for (uint32_t t = 0; t + 2 < 30; ++t)
    mesh.triangles.insert(mesh.triangles.end(), {t, t + 1, t + 2});
  const std::string path = scratch.file("mesh.ply");
  io::write_mesh_ply(path, mesh);
  const map::Mesh read = io::read_mesh_ply(path);
  ASSERT_EQ(read.vertices_m.size(), mesh.vertices_m.size());
  for (size_t v = 0; v < mesh.vertices_m.size(); ++v) {
    EXPECT_EQ(read.vertices_m[v].x, mesh.vertices_m[v].x);
    EXPECT_EQ(read.vertices_m[v].y, mesh.vertices_m[v].y);
    EXPECT_EQ(read.vertices_m[v].z, mesh.vertices_m[v].z);
    EXPECT_EQ(read.colors[v].r, mesh.colors[v].r);
    EXPECT_EQ(read.colors[v].g, mesh.colors[v].g);
    EXPECT_EQ(read.colors[v].b, mesh.colors[v].b);
  }
  EXPECT_EQ(read.triangles, mesh.triangles);
}

// The writers (mesh, trajectory, map) replace a file through a temporary and a rename; a path that
// is not a regular file must be written in place, or `--mesh /dev/null` run as root would replace
// /dev/null with a plain file (seen: two runs writing /dev/null at once also collided on one
// temporary). A FIFO stands in for /dev/null here, so a regression breaks nothing but the test.
TEST(IoFileWriting, NonRegularFileIsWrittenInPlaceNotReplaced) {
  ScratchFolder scratch;
  const std::string fifo = scratch.file("pipe");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  // A non-blocking reader opened first: the writer's open does not wait, the few bytes fit the
  // pipe's buffer, and a writer that replaced the FIFO leaves the read empty instead of hanging.
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0) << std::strerror(errno);
  io::Trajectory trajectory;
  trajectory.poses.push_back({1.5, Eigen::Vector3d(1, 2, 3), Eigen::Quaterniond::Identity()});
  io::write_tum_trajectory(fifo, trajectory);
  std::string received(4096, '\0');
  const ssize_t got = ::read(reader, &received[0], received.size());
  ::close(reader);
  received.resize(got > 0 ? static_cast<size_t>(got) : 0);
  EXPECT_NE(received.find("1.5"), std::string::npos) << received;
  struct stat status {};
  ASSERT_EQ(::stat(fifo.c_str(), &status), 0);
  EXPECT_TRUE(S_ISFIFO(status.st_mode)) << "the FIFO was replaced by a plain file";
  for (const auto& entry : std::filesystem::directory_iterator(scratch.path())) {
    EXPECT_EQ(entry.path().filename().string(), "pipe") << "left behind: " << entry.path();
  }
}

TEST(IoFileWriting, RegularFileIsReplacedWholeAndAFailedOrThrowingWriteKeepsTheOldOne) {
  ScratchFolder scratch;
  const std::string path = scratch.file("out.txt");
  io::write_file_replacing(path, "test", false, [](std::ostream& out) { out << "first"; });
  EXPECT_EQ(io::read_text_file(path), "first");
  io::write_file_replacing(path, "test", false, [](std::ostream& out) { out << "second"; });
  EXPECT_EQ(io::read_text_file(path), "second");
  EXPECT_THROW(io::write_file_replacing(path, "test", false,
                                        [](std::ostream& out) {
                                          out << "half";
                                          out.setstate(std::ios::badbit);
                                        }),
               Error);
  EXPECT_EQ(io::read_text_file(path), "second");
  EXPECT_THROW(io::write_file_replacing(path, "test", false,
                                        [](std::ostream& out) {
                                          out << "part";
                                          throw Error("the writer gave up");
                                        }),
               Error);
  EXPECT_EQ(io::read_text_file(path), "second");
  size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(scratch.path())) {
    (void)entry;
    ++files;
  }
  EXPECT_EQ(files, 1u) << "a temporary was left behind";
  expect_error_mentioning(
      [&] {
        io::write_file_replacing(scratch.file("no/such/dir/x"), "my_writer", false,
                                 [](std::ostream&) {});
      },
      {"my_writer", "no/such/dir/x"});
}

TEST(IoPly, AsciiWithPolygonsExtraPropertiesAndElements) {
  ScratchFolder scratch;
  const std::string path = scratch.file("quad.ply");
  write_text(path,
             "ply\nformat ascii 1.0\ncomment a quad and a triangle\n"
             "element vertex 5\nproperty double x\nproperty double y\nproperty double z\n"
             "property float nx\nproperty list uchar int extra\n"
             "element face 2\nproperty list uint8 uint32 vertex_index\nproperty float quality\n"
             "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
             "0 0 0 0.5 2 7 7\n1 0 0 0.5 0\n1 1 0 0.5 1 9\n0 1 0.25 0.5 0\n2 2 2 1 0\n"
             "4 0 1 2 3 0.9\n3 1 4 2 0.1\n"
             "0 1\n");
  const map::Mesh mesh = io::read_mesh_ply(path);
  ASSERT_EQ(mesh.vertices_m.size(), 5u);
  EXPECT_TRUE(mesh.colors.empty());
  EXPECT_EQ(mesh.vertices_m[3].z, 0.25f);
  EXPECT_EQ(mesh.triangles, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 1, 4, 2}));

  write_text(path,
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float "
             "y\nproperty float z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 1 1\n3 "
             "0 1 2\n");
  expect_error_mentioning([&] { io::read_mesh_ply(path); }, {path, "vertex 2"});
  write_text(path, "ply\nformat binary_big_endian 1.0\nelement vertex 0\nend_header\n");
  expect_error_mentioning([&] { io::read_mesh_ply(path); }, {path, "binary_big_endian"});
  write_text(path,
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float "
             "y\nproperty float z\n"
             "end_header\n0 0 0\n1 1\n");
  expect_error_mentioning([&] { io::read_mesh_ply(path); }, {path, "truncated"});
  write_text(path, "solid ascii stl\n");
  expect_error_mentioning([&] { io::read_mesh_ply(path); }, {path, "not a PLY"});
}

// Each malformed header line is refused naming the file, its line and what was expected.
TEST(IoPly, MalformedHeaderLinesAreRefusedByFileAndLine) {
  ScratchFolder scratch;
  const std::string path = scratch.file("bad.ply");
  const std::string vertex = "element vertex 1\nproperty float x\n";
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"ply\nformat\n" + vertex + "end_header\n", {path + ":2", "format line without"}},
      {"ply\nformat ascii 1.0\nelement vertex\nend_header\n", {path + ":3", "element <name>"}},
      {"ply\nformat ascii 1.0\nelement vertex 2x\nend_header\n", {path + ":3", "<count>"}},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
       {path + ":3", "before any element"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n",
       {path + ":4", "cannot parse property"}},
      {"ply\nformat ascii 1.0\nelement face 1\nproperty list float int idx\nend_header\n",
       {path + ":4", "cannot parse property"}},
      {"ply\nformat ascii 1.0\n" + vertex + "vertices 3\nend_header\n",
       {path + ":5", "unknown PLY header keyword 'vertices'"}},
      {"ply\n" + vertex + "end_header\n0\n", {path, "no format line"}},
      {"ply\nformat ascii 1.0\n" + vertex, {path, "no end_header"}},
  };
  for (const auto& [text, fragments] : cases) {
    SCOPED_TRACE(text);
    write_text(path, text);
    expect_error_mentioning([&] { io::read_mesh_ply(path); }, fragments);
  }
}

TEST(IoPly, ReplicaGroundTruthMesh) {
  COVOX_DATA_OR_SKIP(path, "nvblox-testdata/replica/office0_mesh.ply");
  const map::Mesh mesh = io::read_mesh_ply(path);
  EXPECT_EQ(mesh.vertices_m.size(), 25149u);
  EXPECT_EQ(mesh.triangle_count(), 50000u);
  EXPECT_EQ(mesh.colors.size(), mesh.vertices_m.size());
  Eigen::AlignedBox3f bounds;
  for (const Vec3f& v : mesh.vertices_m) bounds.extend(Eigen::Vector3f(v.x, v.y, v.z));
  const Eigen::Vector3f extent_m = bounds.sizes();
  std::printf("Replica office0 mesh: extent %.2f x %.2f x %.2f m\n", extent_m.x(), extent_m.y(),
              extent_m.z());
  EXPECT_GT(extent_m.minCoeff(), 2.0f);  // a room
  EXPECT_LT(extent_m.maxCoeff(), 15.0f);
}

}  // namespace
}  // namespace covox

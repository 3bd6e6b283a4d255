#include "sim_flight_file.h"

#include <cstdio>
#include <cstring>

#include "covoxslam/core/error.h"

namespace covox {
namespace sim {
namespace {

constexpr char kMagic[8] = {'C', 'O', 'V', 'O', 'X', 'S', 'I', 'M'};
constexpr uint32_t kVersion = 1;
// Offset of the scan count in the header: magic, version, reserved, seed.
constexpr std::streamoff kScanCountOffset = 8 + 4 + 4 + 8;

// The format is little-endian; so are x86 and ARM (Jetson), the only targets, so values are
// written as they lie in memory.
template <class T>
void put(std::ofstream& file, const T& value) {
  file.write(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <class T>
bool get(std::ifstream& file, T* value) {
  return static_cast<bool>(file.read(reinterpret_cast<char*>(value), sizeof(T)));
}

void put_pose(std::ofstream& file, const Eigen::Isometry3d& pose) {
  const Eigen::Quaterniond q(pose.linear());
  for (double v : {pose.translation().x(), pose.translation().y(), pose.translation().z(), q.x(), q.y(), q.z(), q.w()}) {
    put(file, v);
  }
}

bool get_pose(std::ifstream& file, Eigen::Isometry3d* pose) {
  double v[7];
  if (!file.read(reinterpret_cast<char*>(v), sizeof(v))) return false;
  pose->setIdentity();
  pose->translation() = Eigen::Vector3d(v[0], v[1], v[2]);
  pose->linear() = Eigen::Quaterniond(v[6], v[3], v[4], v[5]).normalized().toRotationMatrix();
  return true;
}

}  // namespace

FlightFileWriter::FlightFileWriter(const std::string& path, uint64_t seed, const LidarConfig& lidar)
    : path_(path), temporary_path_(path + ".partial") {
  file_.open(temporary_path_, std::ios::binary | std::ios::trunc);
  if (!file_) throw Error("cannot create flight file '" + temporary_path_ + "' (does the folder exist?)");
  file_.write(kMagic, sizeof(kMagic));
  put(file_, kVersion);
  put(file_, uint32_t{0});
  put(file_, seed);
  put(file_, uint64_t{0});  // scan count, patched by close()
  put(file_, static_cast<uint32_t>(lidar.columns));
  put(file_, static_cast<uint32_t>(lidar.rows));
  for (double v : {lidar.vertical_fov_deg, lidar.min_range_m, lidar.max_range_m, lidar.range_noise_m, lidar.dropout_probability}) {
    put(file_, v);
  }
}

FlightFileWriter::~FlightFileWriter() {
  if (!closed_) {
    file_.close();
    std::remove(temporary_path_.c_str());
  }
}

void FlightFileWriter::write(const FlightScan& scan) {
  put(file_, scan.stamp_s);
  put_pose(file_, scan.truth);
  put_pose(file_, scan.odometry);
  put(file_, static_cast<uint32_t>(scan.points_sensor_m.size()));
  static_assert(sizeof(Vec3f) == 3 * sizeof(float), "Vec3f must be three packed floats");
  file_.write(reinterpret_cast<const char*>(scan.points_sensor_m.data()),
              static_cast<std::streamsize>(scan.points_sensor_m.size() * sizeof(Vec3f)));
  if (!file_) throw Error("writing flight file '" + temporary_path_ + "' failed (disk full?)");
  ++scans_;
}

void FlightFileWriter::close() {
  file_.seekp(kScanCountOffset);
  put(file_, scans_);
  file_.close();
  if (!file_) throw Error("finishing flight file '" + temporary_path_ + "' failed");
  if (std::rename(temporary_path_.c_str(), path_.c_str()) != 0) {
    throw Error("cannot rename '" + temporary_path_ + "' to '" + path_ + "'");
  }
  closed_ = true;
}

FlightFileReader::FlightFileReader(const std::string& path) : path_(path), file_(path, std::ios::binary) {
  if (!file_) throw Error("cannot open flight file '" + path + "' (run simulate_flight first)");
  char magic[8];
  uint32_t reserved = 0, columns = 0, rows = 0;
  double values[5];
  if (!file_.read(magic, sizeof(magic)) || std::memcmp(magic, kMagic, sizeof(kMagic)) != 0) {
    throw Error("'" + path + "' is not a covoxslam flight file (wrong magic)");
  }
  if (!get(file_, &header_.version) || header_.version != kVersion) {
    throw Error("flight file '" + path + "' has version " + std::to_string(header_.version) + "; this build reads version " +
                std::to_string(kVersion) + " (simulate the flight again)");
  }
  if (!get(file_, &reserved) || !get(file_, &header_.seed) || !get(file_, &header_.scan_count) || !get(file_, &columns) ||
      !get(file_, &rows) || !file_.read(reinterpret_cast<char*>(values), sizeof(values))) {
    throw Error("flight file '" + path + "' ends inside its header");
  }
  header_.lidar.columns = static_cast<int>(columns);
  header_.lidar.rows = static_cast<int>(rows);
  header_.lidar.vertical_fov_deg = values[0];
  header_.lidar.min_range_m = values[1];
  header_.lidar.max_range_m = values[2];
  header_.lidar.range_noise_m = values[3];
  header_.lidar.dropout_probability = values[4];
}

bool FlightFileReader::next(FlightScan* scan) {
  if (read_ >= header_.scan_count) return false;
  uint32_t count = 0;
  if (!get(file_, &scan->stamp_s) || !get_pose(file_, &scan->truth) || !get_pose(file_, &scan->odometry) ||
      !get(file_, &count)) {
    throw Error("flight file '" + path_ + "' is truncated at scan " + std::to_string(read_));
  }
  scan->points_sensor_m.resize(count);
  if (!file_.read(reinterpret_cast<char*>(scan->points_sensor_m.data()), static_cast<std::streamsize>(count * sizeof(Vec3f)))) {
    throw Error("flight file '" + path_ + "' is truncated inside scan " + std::to_string(read_));
  }
  ++read_;
  return true;
}

io::Trajectory to_trajectory(const std::vector<StampedIsometry>& poses) {
  io::Trajectory trajectory;
  trajectory.poses.reserve(poses.size());
  for (const StampedIsometry& stamped : poses) {
    io::StampedPose pose;
    pose.timestamp_s = stamped.stamp_s;
    pose.position_m = stamped.pose.translation();
    // Normalised so that a rotation block a little off orthonormal (poses composed over many
    // steps) still gives the unit quaternion TUM files expect.
    pose.orientation = Eigen::Quaterniond(stamped.pose.linear()).normalized();
    trajectory.poses.push_back(pose);
  }
  return trajectory;
}

}  // namespace sim
}  // namespace covox

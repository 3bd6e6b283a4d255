#pragma once
// The simulated-flight file (".covoxsim"): everything the mapping and SLAM runs need from one
// simulated flight, with no ROS dependency. Little-endian throughout:
//
//   header
//     char[8]   magic "COVOXSIM"
//     uint32    version (1)
//     uint32    reserved (0)
//     uint64    seed the flight was simulated from
//     uint64    scan count
//     uint32    LiDAR columns, uint32 rows
//     float64   vertical FOV (deg), min range (m), max range (m), range noise (m), dropout prob.
//   per scan, scan count times
//     float64   stamp (s)
//     float64[7] truth pose T_world_sensor:    tx ty tz qx qy qz qw  (m, unit quaternion)
//     float64[7] odometry pose T_odom_sensor:  tx ty tz qx qy qz qw
//     uint32    point count N
//     float32[3N] points x y z in the sensor frame (m)
//
// The writer puts the scan count in when it is closed and renames a temporary file into place, so
// a simulation cut short never leaves a file that looks complete (the demo caches flights).
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/core/vec3.h"
#include "covoxslam/io/trajectory_io.h"
#include "sim_flight.h"
#include "sim_lidar.h"

namespace covox {
namespace sim {

struct FlightScan {
  double stamp_s = 0.0;
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d odometry = Eigen::Isometry3d::Identity();
  std::vector<Vec3f> points_sensor_m;
};

struct FlightFileHeader {
  uint32_t version = 1;
  uint64_t seed = 0;
  uint64_t scan_count = 0;
  LidarConfig lidar;
};

class FlightFileWriter {
 public:
  FlightFileWriter(const std::string& path, uint64_t seed, const LidarConfig& lidar);
  ~FlightFileWriter();  // an unclosed writer removes its temporary file
  void write(const FlightScan& scan);
  // Patches the scan count and renames the file into place. Throws covox::Error on I/O failure.
  void close();

 private:
  std::string path_, temporary_path_;
  std::ofstream file_;
  uint64_t scans_ = 0;
  bool closed_ = false;
};

class FlightFileReader {
 public:
  // Throws covox::Error for a missing file, a wrong magic or an unsupported version.
  explicit FlightFileReader(const std::string& path);
  const FlightFileHeader& header() const { return header_; }
  // The next scan; false after the last. Throws covox::Error on a truncated file.
  bool next(FlightScan* scan);

 private:
  std::string path_;
  std::ifstream file_;
  FlightFileHeader header_;
  uint64_t read_ = 0;
};

// A flight's poses as an io::Trajectory with orientations, for TUM files and trajectory
// evaluation (the simulator writes truth and odometry with it, map_flight evaluates them).
io::Trajectory to_trajectory(const std::vector<StampedIsometry>& poses);

}  // namespace sim
}  // namespace covox

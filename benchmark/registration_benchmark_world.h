#pragma once
// Registration-heavy 4-DoF pose graphs for benchmark_backend, as voxgraph solves them: submaps
// along a trajectory, odometry between consecutive submaps, and dense registration terms
// (thousands of points per overlapping pair, each an ESDF/TSDF lookup) between neighbours, built
// from a few real submaps of a periodic simulated street (RegistrationWorldConfig says how).
#include <cstdint>
#include <memory>
#include <vector>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/registration_terms.h"
#include "covoxslam/core/device.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace tools {

// Building a thousand real submaps (a LiDAR scan, TSDF and ESDF each) takes too long on a small
// CPU, so the benchmark builds `distinct_submaps` real ones and reuses their fields along a long
// trajectory: the world is a street whose buildings, cars, poles and trees repeat with period
// L = distinct_submaps * spacing_m, the distinct submaps are scanned at poses spread over one
// period (x = m * spacing, with a periodic sideways, height and heading wobble), and submap k of
// the long trajectory is distinct submap k mod M shifted by floor(k / M) * L. Because the world
// repeats, the relative pose and the overlap of submaps k and k + d are those of distinct submaps
// k mod M and (k + d) mod M, shifted by a whole period where they wrap: every registration term is
// a real one. The trajectory is a straight street of n * spacing metres.
struct RegistrationWorldConfig {
  int distinct_submaps = 12;
  double spacing_m = 4.0;  // between consecutive submaps
  float voxel_size_m = 0.2f;
  int lidar_columns = 1024;  // OS1-64-like sensor, 64 rows
  double max_range_m = 25.0;
  int points_per_submap = 2000;  // registration points (sampling_ratio chosen per submap)
  uint64_t seed = 7;
};

// The distinct submaps, built on one device.
struct RegistrationWorld {
  RegistrationWorldConfig config;
  double period_m = 0.0;
  std::vector<backend::Pose4Dof> poses;  // of the distinct submaps within one period
  std::vector<std::unique_ptr<map::TsdfMap>> maps;
  std::vector<std::unique_ptr<backend::RegistrationPoints>> points;
  double build_time_s = 0.0;
};

RegistrationWorld build_registration_world(const RegistrationWorldConfig& config, Device device);

struct RegistrationGraphOptions {
  int submaps = 50;
  int neighbours_ahead = 2;        // terms k -> k + d for d = 1..neighbours_ahead, and k + 1 -> k
  double odometry_sigma_m = 0.04;  // noise of the odometry between consecutive submaps
  double odometry_sigma_rad = 0.005;
  backend::RegistrationDistance distance = backend::RegistrationDistance::kTsdfNearSurface;
  backend::RobustLoss loss = backend::RobustLoss::kHuber;
  double loss_scale = 1.0;      // in units of residual_sigma
  double residual_sigma = 1.0;  // registration residual noise (RegistrationTerm::residual_sigma)
  uint64_t seed = 11;
};

struct RegistrationGraph {
  backend::PoseGraph4Dof graph;  // initial guess: the odometry chained from the true first pose
  std::vector<backend::RegistrationTerm> terms;  // point into the world's maps and points
  std::vector<backend::Pose4Dof> truth;
};

RegistrationGraph make_registration_graph(const RegistrationWorld& world,
                                          const RegistrationGraphOptions& options);

// Root mean square position error (m) of `poses` against `truth`.
double position_rmse_m(const std::vector<backend::Pose4Dof>& poses,
                       const std::vector<backend::Pose4Dof>& truth);

}  // namespace tools
}  // namespace covox

#include "benchmark/registration_benchmark_world.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "sim/sim_lidar.h"
#include "sim/sim_random.h"
#include "sim/sim_world.h"

namespace covox {
namespace tools {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;

// One period of the street, placed at x offset `shift_m`; the same random draws every period.
void add_street_period(sim::World* world, double period_m, double shift_m, uint64_t seed) {
  sim::Random random(seed);
  // Buildings on both sides: blocks of random length, depth and height with gaps between them.
  for (const double side : {1.0, -1.0}) {
    double x = 0.0;
    while (x < period_m) {
      const double length = random.uniform(5.0, 14.0);
      const double depth = random.uniform(5.0, 10.0);
      const double height = random.uniform(4.0, 12.0);
      const double setback = random.uniform(7.0, 10.0);
      sim::Box building;
      building.centre_m =
          Eigen::Vector3d(shift_m + x + 0.5 * length, side * (setback + 0.5 * depth), 0.5 * height);
      building.half_extent_m = Eigen::Vector3d(0.5 * length, 0.5 * depth, 0.5 * height);
      const double yaw = random.uniform(-0.15, 0.15);
      building.rotation = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      world->add(building);
      x += length + random.uniform(1.0, 5.0);
    }
  }
  // Parked cars, poles and trees near the road: structure at every height the sensor sees.
  const int cars = static_cast<int>(period_m / 8.0);
  for (int k = 0; k < cars; ++k) {
    sim::Box car;
    const double side = random.uniform() < 0.5 ? 1.0 : -1.0;
    car.centre_m = Eigen::Vector3d(shift_m + random.uniform(0.0, period_m),
                                   side * random.uniform(4.0, 5.0), 0.75);
    car.half_extent_m = Eigen::Vector3d(2.1, 0.9, 0.75);
    car.rotation =
        Eigen::AngleAxisd(random.uniform(-0.2, 0.2), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    world->add(car);
  }
  const int poles = static_cast<int>(period_m / 6.0);
  for (int k = 0; k < poles; ++k) {
    const double side = random.uniform() < 0.5 ? 1.0 : -1.0;
    world->add(sim::Cylinder{Eigen::Vector3d(shift_m + random.uniform(0.0, period_m),
                                             side * random.uniform(5.5, 6.5), 0.0),
                             random.uniform(0.1, 0.2),
                             random.uniform(4.0, 7.0),
                             {}});
  }
  const int trees = static_cast<int>(period_m / 10.0);
  for (int k = 0; k < trees; ++k) {
    const double side = random.uniform() < 0.5 ? 1.0 : -1.0;
    const Eigen::Vector3d base(shift_m + random.uniform(0.0, period_m),
                               side * random.uniform(5.5, 6.5), 0.0);
    const double trunk = random.uniform(2.0, 3.5);
    world->add(sim::Cylinder{base, 0.2, trunk + 0.3, {}});
    world->add(
        sim::Sphere{base + Eigen::Vector3d(0.0, 0.0, trunk + 1.2), random.uniform(1.2, 2.0), {}});
  }
}

backend::Pose4Dof distinct_pose(const RegistrationWorldConfig& c, int m) {
  const double phase = kTwoPi * m / c.distinct_submaps;
  return backend::Pose4Dof{m * c.spacing_m, 0.8 * std::sin(phase),
                           1.8 + 0.2 * std::sin(2.0 * phase), 0.12 * std::sin(phase + 0.7)};
}

Eigen::Isometry3d isometry_of(const backend::Pose4Dof& pose) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(pose.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(pose.x, pose.y, pose.z);
  return t;
}

// x_a^-1 x_b in frame a (the odometry measurement).
backend::Pose4Dof relative(const backend::Pose4Dof& a, const backend::Pose4Dof& b) {
  const double c = std::cos(a.yaw), s = std::sin(a.yaw);
  const double dx = b.x - a.x, dy = b.y - a.y;
  return backend::Pose4Dof{c * dx + s * dy, -s * dx + c * dy, b.z - a.z, b.yaw - a.yaw};
}

backend::Pose4Dof compose(const backend::Pose4Dof& a, const backend::Pose4Dof& delta) {
  const double c = std::cos(a.yaw), s = std::sin(a.yaw);
  return backend::Pose4Dof{a.x + c * delta.x - s * delta.y, a.y + s * delta.x + c * delta.y,
                           a.z + delta.z, a.yaw + delta.yaw};
}

}  // namespace

RegistrationWorld build_registration_world(const RegistrationWorldConfig& config, Device device) {
  if (config.distinct_submaps < 3)
    throw Error("registration world: distinct_submaps must be at least 3");
  if (!(config.spacing_m > 0.0) || !(config.max_range_m > 0.0)) {
    throw Error("registration world: spacing_m and max_range_m must be positive");
  }
  const auto start = std::chrono::steady_clock::now();
  RegistrationWorld out;
  out.config = config;
  out.period_m = config.distinct_submaps * config.spacing_m;
  sim::World world;
  sim::Plane ground;
  ground.mesh_half_size_m = 1e4;
  world.add(ground);
  // Enough copies of the period to fill the sensor's range around every distinct submap.
  const int copies = static_cast<int>(std::ceil(config.max_range_m / out.period_m)) + 1;
  for (int p = -copies; p <= copies; ++p)
    add_street_period(&world, out.period_m, p * out.period_m, config.seed);
  world.build();

  sim::LidarConfig lidar;
  lidar.columns = config.lidar_columns;
  lidar.max_range_m = config.max_range_m;
  integrators::TsdfIntegratorConfig tsdf_config;
  tsdf_config.truncation_distance_m = 3.0f * config.voxel_size_m;
  tsdf_config.max_ray_length_m = static_cast<float>(config.max_range_m);
  integrators::TsdfIntegrator integrator(tsdf_config);
  integrators::EsdfIntegratorConfig esdf_config;
  esdf_config.esdf_max_distance_m = 2.0f;
  integrators::EsdfIntegrator esdf(esdf_config);
  const Stream stream(device);
  for (int m = 0; m < config.distinct_submaps; ++m) {
    const backend::Pose4Dof pose = distinct_pose(config, m);
    out.poses.push_back(pose);
    // The submap frame is the gravity-aligned sensor pose at its scan: points in that frame.
    const std::vector<Vec3f> scan =
        sim::simulate_scan(world, lidar, isometry_of(pose), sim::stream_seed(config.seed, m));
    auto map =
        std::make_unique<map::TsdfMap>(device, map::TsdfMapConfig{config.voxel_size_m, 8, {}});
    integrator.integrate(*map, scan, {}, Eigen::Isometry3d::Identity());
    esdf.update_all(*map, stream);
    // Sample about points_per_submap of the surface voxels.
    backend::RegistrationPointsConfig points_config;
    points_config.sampling_ratio = 1.0f;
    const int64_t surface =
        backend::extract_registration_points(*map, points_config, stream).surface_voxels;
    points_config.sampling_ratio = static_cast<float>(std::min(
        1.0, config.points_per_submap / std::max<double>(1.0, static_cast<double>(surface))));
    out.points.push_back(std::make_unique<backend::RegistrationPoints>(
        backend::extract_registration_points(*map, points_config, stream)));
    out.maps.push_back(std::move(map));
  }
  out.build_time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

RegistrationGraph make_registration_graph(const RegistrationWorld& world,
                                          const RegistrationGraphOptions& options) {
  if (options.submaps < 2) throw Error("registration graph: needs at least 2 submaps");
  if (options.neighbours_ahead < 1)
    throw Error("registration graph: neighbours_ahead must be at least 1");
  const int m_count = static_cast<int>(world.poses.size());
  RegistrationGraph out;
  for (int k = 0; k < options.submaps; ++k) {
    backend::Pose4Dof pose = world.poses[k % m_count];
    pose.x += (k / m_count) * world.period_m;
    out.truth.push_back(pose);
  }
  sim::Random random(options.seed);
  const Eigen::Vector4d sigma(options.odometry_sigma_m, options.odometry_sigma_m,
                              options.odometry_sigma_m, options.odometry_sigma_rad);
  const Eigen::Matrix4d information = sigma.cwiseInverse().cwiseAbs2().asDiagonal();
  out.graph.poses.push_back(out.truth[0]);
  for (int k = 0; k + 1 < options.submaps; ++k) {
    backend::Pose4Dof measured = relative(out.truth[k], out.truth[k + 1]);
    measured.x += options.odometry_sigma_m * random.normal();
    measured.y += options.odometry_sigma_m * random.normal();
    measured.z += options.odometry_sigma_m * random.normal();
    measured.yaw += options.odometry_sigma_rad * random.normal();
    out.graph.constraints.push_back(
        backend::make_relative_constraint_4dof(k, k + 1, measured, information));
    out.graph.poses.push_back(compose(out.graph.poses.back(), measured));
  }
  out.graph.fixed_vertex = 0;
  auto add_term = [&](int i, int j) {
    backend::RegistrationTerm term;
    term.vertex_i = i;
    term.vertex_j = j;
    term.points_i = world.points[i % m_count].get();
    term.map_j = world.maps[j % m_count].get();
    term.residual.distance = options.distance;
    term.residual.tsdf_band_m = 2.0f * world.config.voxel_size_m;
    term.residual.loss = options.loss;
    term.residual.loss_scale = options.loss_scale;
    term.residual_sigma = options.residual_sigma;
    out.terms.push_back(term);
  };
  for (int k = 0; k < options.submaps; ++k) {
    for (int d = 1; d <= options.neighbours_ahead && k + d < options.submaps; ++d)
      add_term(k, k + d);
    if (k + 1 < options.submaps) add_term(k + 1, k);
  }
  return out;
}

double position_rmse_m(const std::vector<backend::Pose4Dof>& poses,
                       const std::vector<backend::Pose4Dof>& truth) {
  double sum = 0.0;
  for (size_t k = 0; k < poses.size(); ++k) {
    sum += std::pow(poses[k].x - truth[k].x, 2) + std::pow(poses[k].y - truth[k].y, 2) +
           std::pow(poses[k].z - truth[k].z, 2);
  }
  return poses.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(poses.size()));
}

}  // namespace tools
}  // namespace covox

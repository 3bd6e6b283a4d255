// The LiDAR simulator: deterministic from its seed, exact against analytic surfaces, its
// hierarchy finds the same hits as testing every primitive, the odometry drifts at least as much
// as configured, and flight bags are byte-identical for a seed and read back what was written.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>

#include "runner/bag_scan_source.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/rosbag_reader.h"
#include "sim/sim_flight.h"
#include "sim/sim_flight_bag.h"
#include "sim/sim_lidar.h"
#include "sim/sim_random.h"
#include "sim/sim_site.h"
#include "sim/sim_world.h"

namespace covox {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

LidarConfig exact_lidar(int columns = 128, int rows = 32) {
  LidarConfig config;
  config.columns = columns;
  config.rows = rows;
  config.range_noise_m = 0.0;
  config.dropout_probability = 0.0;
  return config;
}

Eigen::Isometry3d pose_at(const Eigen::Vector3d& position_m, double yaw_rad = 0.0) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = position_m;
  return pose;
}

// A world of one closed box to cast from inside: every beam hits a wall.
Box box_room(const Eigen::Vector3d& centre_m, const Eigen::Vector3d& half_extent_m) {
  Box room;
  room.centre_m = centre_m;
  room.half_extent_m = half_extent_m;
  return room;
}
World room_world(const Box& room) {
  World world;
  world.add(room);
  world.build();
  return world;
}

// Bit for bit.
bool same_point(const Vec3f& a, const Vec3f& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

Eigen::Vector3d to_world(const Eigen::Isometry3d& pose, const Vec3f& p) {
  return pose * Eigen::Vector3d(p.x, p.y, p.z);
}

TEST(Simulator, SameSeedGivesIdenticalScansAndOdometry) {
  const FlightConfig flight;
  const Figure8Path path(flight);
  const std::vector<StampedIsometry> truth = simulate_truth(path, flight);
  LidarConfig lidar;
  lidar.columns = 128;  // noise and dropouts on, as in a real run
  std::vector<std::vector<Vec3f>> runs[2];
  std::vector<StampedIsometry> odometry[2];
  for (int run = 0; run < 2; ++run) {
    const Site site = build_site(SiteConfig(), path, 42);
    odometry[run] = simulate_odometry(truth, DriftConfig(), 42);
    for (size_t k : {size_t{0}, truth.size() / 4, truth.size() / 2}) {
      runs[run].push_back(simulate_scan(site.world, lidar, truth[k].pose, stream_seed(42, k)));
    }
  }
  ASSERT_EQ(runs[0].size(), runs[1].size());
  for (size_t s = 0; s < runs[0].size(); ++s) {
    ASSERT_GT(runs[0][s].size(), 1000u);
    ASSERT_EQ(runs[0][s].size(), runs[1][s].size());
    for (size_t i = 0; i < runs[0][s].size(); ++i) {
      ASSERT_EQ(runs[0][s][i].x, runs[1][s][i].x);
      ASSERT_EQ(runs[0][s][i].y, runs[1][s][i].y);
      ASSERT_EQ(runs[0][s][i].z, runs[1][s][i].z);
    }
  }
  for (size_t k = 0; k < truth.size(); ++k) {
    ASSERT_TRUE(odometry[0][k].pose.isApprox(odometry[1][k].pose, 0.0));
  }
  // Another seed changes the noise.
  const Site site = build_site(SiteConfig(), path, 42);
  const std::vector<Vec3f> other =
      simulate_scan(site.world, lidar, truth[0].pose, stream_seed(43, 0));
  bool differs = other.size() != runs[0][0].size();
  for (size_t i = 0; !differs && i < other.size(); ++i) differs = other[i].x != runs[0][0][i].x;
  EXPECT_TRUE(differs);
}

TEST(Simulator, ALargerFigureEightGetsAProportionallyBuiltUpSite) {
  // The default flight's site, and any figure 8 of the default lobes, keep the configured counts.
  FlightConfig flight;
  const SiteConfig base;
  for (double path_m : {400.0, 495.0, 3600.0}) {
    flight.path_length_m = path_m;
    const SiteConfig same = base.scaled_to(Figure8Path(flight));
    EXPECT_EQ(same.extra_buildings, base.extra_buildings) << path_m;
    EXPECT_EQ(same.trees, base.trees) << path_m;
  }
  // Lobes twice as long and a lap twice as long: four times the area, four times the objects.
  flight.lobe_half_length_m = 2.0 * FlightConfig().lobe_half_length_m;
  flight.path_length_m = 2.0 * 9.0 * flight.lobe_half_length_m;
  const Figure8Path large(flight);
  const SiteConfig scaled = base.scaled_to(large);
  EXPECT_NEAR(scaled.extra_buildings, 4 * base.extra_buildings, 1);
  EXPECT_NEAR(scaled.rubble_piles, 4 * base.rubble_piles, 1);
  EXPECT_NEAR(scaled.poles, 4 * base.poles, 2);
  EXPECT_NEAR(scaled.trees, 4 * base.trees, 2);
  const Site site = build_site(scaled, large, 5);
  EXPECT_EQ(site.buildings.size(), static_cast<size_t>(1 + scaled.extra_buildings));
}

TEST(Simulator, AFlightShorterThanALapFliesTheStartOfTheDefaultFlight) {
  // 10 s at 2 m/s: 20 m, shorter than any figure 8 of the default lobes can be. It flies the
  // default flight's first 20 m, pose for pose, and ends there.
  const FlightConfig full;
  FlightConfig short_flight;
  short_flight.path_length_m = 20.0;
  const Figure8Path full_path(full), short_path(short_flight);
  EXPECT_DOUBLE_EQ(short_path.lap_length_m(), full_path.lap_length_m());
  const std::vector<StampedIsometry> truth = simulate_truth(short_path, short_flight);
  ASSERT_GE(truth.size(), 100u);
  EXPECT_LE(truth.size(), 102u);
  // The last pose is where the short flight stops: the same place, level as a hovering drone.
  for (const StampedIsometry& pose : truth) {
    const double t_s = pose.stamp_s - short_flight.start_time_s;
    const Eigen::Isometry3d expected = truth_pose_at(full_path, full, t_s);
    ASSERT_TRUE(pose.pose.translation().isApprox(expected.translation(), 1e-12)) << t_s;
    if (&pose != &truth.back()) ASSERT_TRUE(pose.pose.isApprox(expected, 1e-12)) << t_s;
  }
  const double flown_m =
      (truth.back().pose.translation() - truth.front().pose.translation()).norm();
  EXPECT_GT(flown_m, 15.0);
  EXPECT_LE(flown_m, 20.0 + 1e-6);
  // A lap given explicitly that these lobes cannot fly is still refused.
  short_flight.lap_length_m = 20.0;
  EXPECT_THROW(Figure8Path{short_flight}, Error);
}

TEST(Simulator, RangesMatchAnalyticDistancesToAPlane) {
  World world;
  world.add(Plane{});  // z = 0, facing up
  world.build();
  const LidarConfig lidar = exact_lidar();
  const Eigen::Isometry3d pose = pose_at(Eigen::Vector3d(1.0, -2.0, 2.0), 0.4);
  const std::vector<Vec3f> points = simulate_scan(world, lidar, pose, 1);
  // Every beam looking down hits the plane at range height / sin(-elevation), and returns when
  // that is within the range limit.
  int downward = 0;
  for (int row = 0; row < lidar.rows; ++row) {
    const double down = -beam_direction(lidar, row, 0).z();
    if (down > 0.0 && 2.0 / down <= lidar.max_range_m) downward += lidar.columns;
  }
  ASSERT_EQ(static_cast<int>(points.size()), downward);
  for (const Vec3f& p : points) {
    const Eigen::Vector3d local(p.x, p.y, p.z);
    const double expected = 2.0 / (-local.normalized().z());
    EXPECT_NEAR(local.norm(), expected, 1e-5 * expected);
    EXPECT_NEAR(to_world(pose, p).z(), 0.0, 1e-5 * expected);
  }
}

TEST(Simulator, RangesMatchAnalyticDistancesInsideABoxRoom) {
  const Box room = box_room(Eigen::Vector3d(0.5, 0.0, 1.0), Eigen::Vector3d(4.0, 3.0, 2.5));
  const World world = room_world(room);
  const LidarConfig lidar = exact_lidar();
  const Eigen::Isometry3d pose = pose_at(Eigen::Vector3d(0.0, 0.5, 1.2), -0.3);
  const std::vector<Vec3f> points = simulate_scan(world, lidar, pose, 1);
  ASSERT_EQ(static_cast<int>(points.size()),
            lidar.columns * lidar.rows);  // a closed room: every beam hits
  for (const Vec3f& p : points) {
    // Exit distance through the nearest wall, face by face.
    const Eigen::Vector3d direction = pose.linear() * Eigen::Vector3d(p.x, p.y, p.z).normalized();
    const Eigen::Vector3d origin = pose.translation() - room.centre_m;
    double expected = kNoHit;
    for (int axis = 0; axis < 3; ++axis) {
      if (std::abs(direction[axis]) < 1e-12) continue;
      const double wall =
          direction[axis] > 0 ? room.half_extent_m[axis] : -room.half_extent_m[axis];
      expected = std::min(expected, (wall - origin[axis]) / direction[axis]);
    }
    EXPECT_NEAR(Eigen::Vector3d(p.x, p.y, p.z).norm(), expected, 1e-5 * expected);
  }
}

TEST(Simulator, RangesMatchAnalyticDistancesToACylinder) {
  World world;
  Cylinder pole;
  pole.base_centre_m = Eigen::Vector3d(6.0, 1.0, -10.0);
  pole.radius_m = 1.5;
  pole.height_m = 20.0;
  world.add(pole);
  world.build();
  const LidarConfig lidar = exact_lidar(720, 16);
  const Eigen::Isometry3d pose = pose_at(Eigen::Vector3d(0.0, 0.0, 0.0), 0.2);
  const std::vector<Vec3f> points = simulate_scan(world, lidar, pose, 1);
  ASSERT_GT(points.size(), 100u);
  for (const Vec3f& p : points) {
    const Eigen::Vector3d world_point = to_world(pose, p);
    // On the mantle, and the nearer of the two crossings: the one facing the sensor.
    EXPECT_NEAR((world_point - pole.base_centre_m).head<2>().norm(), pole.radius_m, 1e-4);
    const Eigen::Vector2d outward = (world_point - pole.base_centre_m).head<2>();
    EXPECT_LT(outward.dot((world_point - pose.translation()).head<2>()), 0.0);
  }
  // The beam straight at the axis measures the distance to the axis minus the radius.
  const double expected =
      (pole.base_centre_m.head<2>() - pose.translation().head<2>()).norm() - pole.radius_m;
  const Eigen::Vector3d towards = (pose.inverse() * Eigen::Vector3d(6.0, 1.0, 0.0)).normalized();
  EXPECT_NEAR(world.intersect(pose.translation(), pose.linear() * towards), expected, 1e-9);
}

TEST(SimulatorSweep, ColumnTimesIncreaseAndSpanOneSweep) {
  for (const int columns : {64, 256, 1024, 2048}) {
    const LidarConfig lidar = exact_lidar(columns, 4);
    const double period_s = 0.1;
    EXPECT_EQ(column_time_ns(lidar, period_s, 0), 0u);
    for (int column = 1; column < columns; ++column) {
      ASSERT_GT(column_time_ns(lidar, period_s, column),
                column_time_ns(lidar, period_s, column - 1))
          << columns << " " << column;
    }
    // The last column fires one column's time before the sweep ends.
    EXPECT_NEAR(column_time_ns(lidar, period_s, columns - 1), 1e8 * (columns - 1) / columns, 0.5);
    EXPECT_LT(column_time_ns(lidar, period_s, columns - 1), 100000000u);
  }
  // The scan's points carry the time of their beam's column, found from the point's azimuth.
  const World world = room_world(box_room(Eigen::Vector3d::Zero(), Eigen::Vector3d(6.0, 5.0, 4.0)));
  const LidarConfig lidar = exact_lidar(90, 8);
  const SweepScan scan = simulate_sweep(
      world, lidar, [](double) { return pose_at(Eigen::Vector3d(0.5, 0.0, 0.0)); }, 0.1, 1);
  ASSERT_EQ(scan.points_sensor_m.size(), 90u * 8u);
  ASSERT_EQ(scan.times_ns.size(), scan.points_sensor_m.size());
  for (size_t i = 0; i < scan.points_sensor_m.size(); ++i) {
    const Vec3f& p = scan.points_sensor_m[i];
    const double azimuth_deg = std::atan2(p.y, p.x) * 180.0 / kPi;
    const int column = static_cast<int>(std::lround(
                           (azimuth_deg < -0.5 ? azimuth_deg + 360.0 : azimuth_deg) / 4.0)) %
                       90;
    ASSERT_EQ(scan.times_ns[i], static_cast<uint32_t>(std::llround(column * 1e8 / 90.0))) << i;
  }
}

// A world point's distance to the nearest face of `room` (the sensor is inside).
double distance_to_walls(const Box& room, const Eigen::Vector3d& point_m) {
  const Eigen::Vector3d local = (point_m - room.centre_m).cwiseAbs();
  return (room.half_extent_m - local).minCoeff();
}

TEST(SimulatorSweep, StillSensorGivesTheInstantaneousScan) {
  const Site site = build_site(SiteConfig(), Figure8Path(FlightConfig()), 3);
  LidarConfig lidar;
  lidar.columns = 128;  // noise and dropouts on: they are the same either way
  LidarConfig instantaneous = lidar;
  instantaneous.instantaneous = true;
  const Eigen::Isometry3d pose = pose_at(Eigen::Vector3d(10.0, 2.0, 3.5), 0.7);
  const PoseAtTime still = [&](double) { return pose; };
  const SweepScan distorted = simulate_sweep(site.world, lidar, still, 0.1, 17);
  const SweepScan at_once = simulate_sweep(site.world, instantaneous, still, 0.1, 17);
  const std::vector<Vec3f> reference = simulate_scan(site.world, lidar, pose, 17);
  ASSERT_GT(reference.size(), 1000u);
  ASSERT_EQ(distorted.points_sensor_m.size(), reference.size());
  ASSERT_EQ(at_once.points_sensor_m.size(), reference.size());
  EXPECT_EQ(distorted.times_ns.size(), reference.size());
  EXPECT_TRUE(at_once.times_ns.empty());
  for (size_t i = 0; i < reference.size(); ++i) {
    ASSERT_TRUE(same_point(distorted.points_sensor_m[i], reference[i])) << i;
    ASSERT_TRUE(same_point(at_once.points_sensor_m[i], reference[i])) << i;
  }
}

TEST(SimulatorSweep, MovingSensorCastsEachColumnFromItsPoseAtItsTime) {
  const Box room = box_room(Eigen::Vector3d(1.0, 0.5, 1.0), Eigen::Vector3d(9.0, 7.0, 3.0));
  const World world = room_world(room);
  const LidarConfig lidar = exact_lidar(120, 16);
  // 2 m/s forward, climbing at 0.5 m/s, yawing at 60 deg/s.
  const PoseAtTime moving = [](double t) {
    return pose_at(Eigen::Vector3d(-1.0 + 2.0 * t, 0.3, 1.0 + 0.5 * t), 0.2 + kPi / 3.0 * t);
  };
  const SweepScan scan = simulate_sweep(world, lidar, moving, 0.1, 5);
  ASSERT_EQ(scan.points_sensor_m.size(), 120u * 16u);  // a closed room: every beam hits
  double largest_shift_m = 0.0;
  const std::vector<Vec3f> at_start = simulate_scan(world, lidar, moving(0.0), 5);
  for (int column = 0; column < lidar.columns; column += 7) {
    const double t = column_time_ns(lidar, 0.1, column) * 1e-9;
    const std::vector<Vec3f> at_firing = simulate_scan(world, lidar, moving(t), 5);
    for (int row = 0; row < lidar.rows; ++row) {
      const size_t i = static_cast<size_t>(row * lidar.columns + column);
      ASSERT_DOUBLE_EQ(scan.times_ns[i] * 1e-9, t);
      // In the sensor frame at its time: the instantaneous cast from the pose at that time, and
      // moved into the world with that pose it lies on the room's walls.
      ASSERT_TRUE(same_point(scan.points_sensor_m[i], at_firing[i])) << row << " " << column;
      EXPECT_NEAR(distance_to_walls(room, to_world(moving(t), scan.points_sensor_m[i])), 0.0, 1e-4);
      largest_shift_m = std::max(largest_shift_m, (to_world(moving(t), scan.points_sensor_m[i]) -
                                                   to_world(moving(0.0), at_start[i]))
                                                      .norm());
    }
  }
  // Late columns see the room from up to 0.2 m further along and 6 degrees further round.
  EXPECT_GT(largest_shift_m, 0.15);
}

TEST(Simulator, HierarchyFindsTheSameHitsAsTestingEveryPrimitive) {
  const Figure8Path path{FlightConfig()};
  const Site site = build_site(SiteConfig(), path, 3);
  Random random(5);
  int hits = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d origin(random.uniform(-60, 60), random.uniform(-40, 40),
                                 random.uniform(0.5, 6.0));
    const Eigen::Vector3d direction =
        Eigen::Vector3d(random.normal(), random.normal(), random.normal()).normalized();
    double brute = kNoHit;
    for (const Box& b : site.world.boxes())
      brute = std::min(brute, intersect(b, origin, direction));
    for (const Cylinder& c : site.world.cylinders())
      brute = std::min(brute, intersect(c, origin, direction));
    for (const Sphere& s : site.world.spheres())
      brute = std::min(brute, intersect(s, origin, direction));
    for (const Triangle& t : site.world.triangles())
      brute = std::min(brute, intersect(t, origin, direction));
    const double fast = site.world.intersect(origin, direction);
    if (brute == kNoHit) {
      EXPECT_EQ(fast, kNoHit);
    } else {
      ++hits;
      EXPECT_DOUBLE_EQ(fast, brute);
    }
  }
  EXPECT_GT(hits, 1000);
}

TEST(Simulator, FlightHasTheRequestedShapeAndOdometryDriftsAtLeastAsConfigured) {
  const FlightConfig flight;
  const Figure8Path path(flight);
  EXPECT_NEAR(path.length_m(), 400.0, 0.5);
  const std::vector<StampedIsometry> truth = simulate_truth(path, flight);
  EXPECT_EQ(truth.size(), 2001u);  // 200 s at 10 Hz
  EXPECT_NEAR((truth[1].pose.translation() - truth[0].pose.translation()).norm(), 0.2, 0.01);
  // The attitude is continuous from the first pose on: a drone at 2 m/s on this path tilts a few
  // degrees at most, and the first pose like the second.
  for (size_t k = 0; k < truth.size(); ++k) {
    ASSERT_GT(truth[k].pose.linear()(2, 2), std::cos(15.0 * 3.14159265358979323846 / 180.0)) << k;
  }
  EXPECT_GT((truth[0].pose.linear().transpose() * truth[1].pose.linear())(2, 2), 0.9999);
  EXPECT_GT((truth.back().pose.linear().transpose() * truth[truth.size() - 2].pose.linear())(2, 2),
            0.9999);
  for (double minimum_m : {3.0, 6.0}) {
    DriftConfig drift;
    drift.min_final_drift_m = minimum_m;
    const std::vector<StampedIsometry> odometry = simulate_odometry(truth, drift, 11);
    EXPECT_GE(final_drift_m(truth, odometry), minimum_m);
    EXPECT_TRUE(odometry[0].pose.isApprox(truth[0].pose));
    // Drift is in x, y, z and yaw only: roll and pitch stay those of the truth.
    const Eigen::Vector3d truth_up = truth.back().pose.linear().col(2);
    const Eigen::Vector3d odometry_up = odometry.back().pose.linear().col(2);
    EXPECT_NEAR(truth_up.z(), odometry_up.z(), 1e-9);
  }
  // --drift-scale: 0 gives the truth itself; any factor keeps the least final drift.
  const std::vector<StampedIsometry> exact =
      simulate_odometry(truth, DriftConfig().scaled(0.0), 11);
  ASSERT_EQ(exact.size(), truth.size());
  for (size_t k = 0; k < truth.size(); k += 100)
    EXPECT_TRUE(exact[k].pose.isApprox(truth[k].pose, 1e-12)) << k;
  EXPECT_LT(final_drift_m(truth, exact), 1e-9);
  EXPECT_GE(final_drift_m(truth, simulate_odometry(truth, DriftConfig().scaled(0.5), 11)), 3.0);
  EXPECT_THROW(DriftConfig().scaled(-1.0), Error);
}

TEST(Simulator, TruthIsAFunctionOfTimeAndTurnsAsFastAsADrone) {
  const FlightConfig flight;
  const Figure8Path path(flight);
  const std::vector<StampedIsometry> truth = simulate_truth(path, flight);
  // The samples are the function at the samples' times, bit for bit; from their stamps (which
  // round the time a little) the function gives nearly the same poses.
  for (size_t k = 0; k < truth.size(); k += 37) {
    const double t = static_cast<double>(k) * (1.0 / flight.scan_rate_hz);
    ASSERT_TRUE(truth_pose_at(path, flight, t).matrix() == truth[k].pose.matrix()) << k;
    const Eigen::Isometry3d at =
        truth_pose_at(path, flight, truth[k].stamp_s - flight.start_time_s);
    ASSERT_TRUE(at.isApprox(truth[k].pose, 1e-9)) << k;
  }
  // The yaw sweep: a quarter period in, the drone looks the full amplitude left of its heading.
  FlightConfig forward = flight;
  forward.yaw_sweep_amplitude_deg = 0.0;
  const Eigen::Matrix3d swept =
      truth_pose_at(path, flight, 0.25 * flight.yaw_sweep_period_s).linear();
  const Eigen::Matrix3d ahead =
      truth_pose_at(path, forward, 0.25 * flight.yaw_sweep_period_s).linear();
  const double yaw_offset_deg =
      std::remainder(std::atan2(swept(1, 0), swept(0, 0)) - std::atan2(ahead(1, 0), ahead(0, 0)),
                     2.0 * kPi) *
      180.0 / kPi;
  EXPECT_NEAR(yaw_offset_deg, flight.yaw_sweep_amplitude_deg, 1e-9);
  // The default flight turns at up to about 60 deg/s; the path alone, in its tightest turn at
  // 2 m/s, at about 13 deg/s.
  const double peak_deg_per_s = peak_yaw_rate_deg_per_s(path, flight);
  const double path_only_deg_per_s = peak_yaw_rate_deg_per_s(path, forward);
  std::printf("peak yaw rate: %.1f deg/s (path alone %.1f deg/s)\n", peak_deg_per_s,
              path_only_deg_per_s);
  EXPECT_GT(peak_deg_per_s, 55.0);
  EXPECT_LT(peak_deg_per_s, 65.0);
  EXPECT_GT(path_only_deg_per_s, 8.0);
  EXPECT_LT(path_only_deg_per_s, 20.0);
  FlightConfig bad = flight;
  bad.odometry_rate_hz = 25.0;  // not a whole multiple of 10 Hz
  EXPECT_THROW(Figure8Path{bad}, Error);
}

TEST(Simulator, OdometryExistsBetweenTheScanSamples) {
  const FlightConfig flight;
  const Figure8Path path(flight);
  const std::vector<StampedIsometry> truth = simulate_truth(path, flight);
  const std::vector<StampedIsometry> odometry = simulate_odometry(truth, DriftConfig(), 11);
  const auto truth_at = [&](double stamp_s) {
    return truth_pose_at(path, flight, stamp_s - flight.start_time_s);
  };
  const auto drift_at = [&](double stamp_s) {
    return odometry_at(truth, odometry, stamp_s, truth_at(stamp_s)) * truth_at(stamp_s).inverse();
  };
  for (size_t k = 0; k + 1 < truth.size(); k += 53) {
    // At a sample's stamp: the sample itself.
    const Eigen::Isometry3d sample = odometry_at(truth, odometry, truth[k].stamp_s, truth[k].pose);
    ASSERT_TRUE(sample.matrix() == odometry[k].pose.matrix()) << k;
    // Between two samples the drift moves from one sample's to the other's: halfway, the drift's
    // translation is the mean of theirs and its rotation half of the way.
    const Eigen::Isometry3d before = odometry[k].pose * truth[k].pose.inverse();
    const Eigen::Isometry3d after = odometry[k + 1].pose * truth[k + 1].pose.inverse();
    const Eigen::Isometry3d middle = drift_at(0.5 * (truth[k].stamp_s + truth[k + 1].stamp_s));
    EXPECT_LT((middle.translation() - 0.5 * (before.translation() + after.translation())).norm(),
              1e-9);
    const Eigen::Quaterniond q_before(before.linear()), q_after(after.linear());
    EXPECT_TRUE(Eigen::Quaterniond(middle.linear()).isApprox(q_before.slerp(0.5, q_after), 1e-9));
    // Roll and pitch are the truth's: the drift is a yaw.
    EXPECT_NEAR(middle.linear()(2, 2), 1.0, 1e-12);
  }
  // Past the last sample (the last sweep) the last drift holds.
  const double late_s = truth.back().stamp_s + 0.05;
  const Eigen::Isometry3d last = odometry.back().pose * truth.back().pose.inverse();
  EXPECT_TRUE(drift_at(late_s).isApprox(last, 1e-9));
  // Without drift the odometry is the truth at any time.
  const std::vector<StampedIsometry> exact =
      simulate_odometry(truth, DriftConfig().scaled(0.0), 11);
  for (double stamp_s = truth[3].stamp_s + 0.013; stamp_s < truth[40].stamp_s; stamp_s += 0.37)
    EXPECT_TRUE(
        odometry_at(truth, exact, stamp_s, truth_at(stamp_s)).isApprox(truth_at(stamp_s), 1e-12));
}

// Writes the first `scans` scans of the default flight (seed `seed`, a small LiDAR) as a bag and
// returns its bytes.
std::vector<char> simulated_bag_bytes(const std::string& path, uint64_t seed, size_t scans) {
  const FlightConfig flight;
  const Figure8Path path_8(flight);
  const Site site = build_site(SiteConfig(), path_8, seed);
  const std::vector<StampedIsometry> truth = simulate_truth(path_8, flight);
  const std::vector<StampedIsometry> odometry = simulate_odometry(truth, DriftConfig(), seed);
  LidarConfig lidar;
  lidar.columns = 64;
  lidar.rows = 16;
  {
    FlightBagWriter writer(path);
    for (size_t k = 0; k < scans; ++k) {
      writer.write_scan(
          truth[k].stamp_s, truth[k].pose, odometry[k].pose,
          simulate_scan(site.world, lidar, truth[k].pose, stream_seed(seed, 0x5CA7, k)), {});
    }
    writer.close();
  }
  std::ifstream file(path, std::ios::binary);
  return std::vector<char>(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
}

TEST(Simulator, SameSeedGivesAnIdenticalBagAndAnotherSeedAnotherBag) {
  const std::string path = ::testing::TempDir() + "/simulator_test_determinism.bag";
  const std::vector<char> first = simulated_bag_bytes(path, 5, 4);
  const std::vector<char> second = simulated_bag_bytes(path, 5, 4);
  const std::vector<char> other = simulated_bag_bytes(path, 6, 4);
  ASSERT_GT(first.size(), 4096u + 4 * 64 * 16 * 12 / 2);  // header plus at least half the beams
  EXPECT_TRUE(first == second);
  EXPECT_FALSE(first == other);
  std::remove(path.c_str());
}

TEST(Simulator, FlightBagHasTheArcheLayoutAndReadsBackAsWritten) {
  const std::string path = ::testing::TempDir() + "/simulator_test_layout.bag";
  const size_t scans = 3;
  std::vector<Eigen::Isometry3d> truth(scans), odometry(scans);
  std::vector<std::vector<Vec3f>> points(scans);
  {
    FlightBagWriter writer(path);
    for (size_t k = 0; k < scans; ++k) {
      truth[k] = pose_at(Eigen::Vector3d(2.0 * k, 1.0, 3.0), 0.3 * k);
      odometry[k] = pose_at(Eigen::Vector3d(2.0 * k + 0.1 * k, 1.2, 3.0), 0.3 * k + 0.05 * k);
      for (int i = 0; i < 100; ++i) points[k].emplace_back(1.0f + i, 0.5f * i - 20.0f, 0.1f * k);
      writer.write_scan(1000.0 + 0.1 * k, truth[k], odometry[k], points[k], {});
    }
    writer.close();
  }
  const ArcheBagLayout layout;
  io::rosbag::BagReader bag(path);
  EXPECT_EQ(bag.message_count(layout.cloud_topic), scans);
  EXPECT_EQ(bag.message_count("/tf"), scans);
  EXPECT_EQ(bag.message_count("/tf_static"), 1u);
  EXPECT_EQ(bag.message_count(layout.ground_truth_topic), scans);

  // The runner's view: clouds in os1_lidar with the odometry pose of os1_lidar found through
  // odom -> imu -> os1_sensor -> os1_lidar, and the fixes as the reference.
  tools::BagScanSource source(path, tools::BagScanOptions());
  ASSERT_EQ(source.size(), scans);
  ASSERT_EQ(source.reference().size(), scans);
  EXPECT_FALSE(source.reference().has_orientations);
  tools::SourceScan scan;
  for (size_t k = 0; k < scans; ++k) {
    ASSERT_TRUE(source.next(&scan));
    EXPECT_NEAR(scan.stamp_s, 1000.0 + 0.1 * k, 1e-9);
    const Eigen::Isometry3d expected_pose = odometry[k] * T_os1_sensor_os1_lidar();
    EXPECT_TRUE(scan.T_odom_sensor.isApprox(expected_pose, 1e-9)) << "scan " << k;
    ASSERT_EQ(scan.points_sensor_m.size(), points[k].size());
    for (size_t i = 0; i < points[k].size(); ++i) {
      // Same point in the world whichever frame it was written in.
      const Eigen::Vector3d written =
          odometry[k] * Eigen::Vector3d(points[k][i].x, points[k][i].y, points[k][i].z);
      const Eigen::Vector3d read =
          scan.T_odom_sensor * Eigen::Vector3d(scan.points_sensor_m[i].x, scan.points_sensor_m[i].y,
                                               scan.points_sensor_m[i].z);
      ASSERT_LT((written - read).norm(), 1e-4);
    }
    EXPECT_LT((source.reference().poses[k].position_m - truth[k].translation()).norm(), 1e-12);
  }
  EXPECT_FALSE(source.next(&scan));
  EXPECT_EQ(source.dropped(), 0);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace sim
}  // namespace covox

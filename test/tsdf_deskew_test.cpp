// De-skewing (integrators/sweep_motion.h, stage 0 of a TSDF frame): the motion model against
// Eigen's interpolation of the sweep's poses, and a LiDAR that sweeps while it moves through an
// analytic room: de-skewed, its map is the map of the same points moved on the host, and as close
// to the room's true distances as a scan taken at once; not de-skewed, it is clearly worse. The
// CPU and CUDA backends build the same de-skewed map.
#include "covoxslam/integrators/sweep_motion.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/map/tsdf_map.h"
#include "support/analytic_scene.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::AnalyticScene;
using testing_support::DeviceTest;

Eigen::Isometry3d random_pose(std::mt19937& random) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::Quaterniond(unit(random), unit(random), unit(random), unit(random))
                      .normalized()
                      .toRotationMatrix();
  pose.translation() = Eigen::Vector3d(unit(random), unit(random), unit(random)) * 5.0;
  return pose;
}

// The pose at `t` between the sweep's ends: position interpolated linearly, orientation by
// quaternion slerp (Eigen), independent of SweepMotion's rotation-vector form.
Eigen::Isometry3d interpolated(const Eigen::Isometry3d& begin, const Eigen::Isometry3d& end,
                               double alpha) {
  const Eigen::Quaterniond q_begin(begin.linear()), q_end(end.linear());
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = q_begin.slerp(alpha, q_end).toRotationMatrix();
  pose.translation() = (1.0 - alpha) * begin.translation() + alpha * end.translation();
  return pose;
}

TEST(SweepMotion, MovesPointsAsTheInterpolatedPosesDo) {
  std::mt19937 random(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Isometry3d ref = random_pose(random), begin = random_pose(random);
    // Sweeps turn by up to about 60 degrees and move a metre: far beyond a real sweep's motion.
    Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
    step.linear() =
        Eigen::AngleAxisd(unit(random), Eigen::Vector3d::Random().normalized()).toRotationMatrix();
    step.translation() = Eigen::Vector3d::Random();
    const Eigen::Isometry3d end = begin * step;
    const double begin_s = -0.05 + 0.01 * unit(random), end_s = begin_s + 0.1;
    const integrators::SweepMotion motion =
        integrators::make_sweep_motion(ref, begin, end, begin_s, end_s);
    for (int k = 0; k < 5; ++k) {
      const Eigen::Vector3d p = Eigen::Vector3d::Random() * 30.0;
      const double alpha = k / 4.0;
      const double t = begin_s + alpha * (end_s - begin_s);
      const Eigen::Vector3d expected = ref.inverse() * interpolated(begin, end, alpha) * p;
      const Vec3f moved = motion.deskew(Vec3f(float(p.x()), float(p.y()), float(p.z())), float(t));
      EXPECT_NEAR(moved.x, expected.x(), 1e-4 * (1.0 + expected.norm())) << trial << " " << k;
      EXPECT_NEAR(moved.y, expected.y(), 1e-4 * (1.0 + expected.norm())) << trial << " " << k;
      EXPECT_NEAR(moved.z, expected.z(), 1e-4 * (1.0 + expected.norm())) << trial << " " << k;
    }
  }
}

TEST(SweepMotion, ClampsTimesOutsideTheSweepAndPassesNonFiniteOnes) {
  Eigen::Isometry3d begin = Eigen::Isometry3d::Identity(), end = Eigen::Isometry3d::Identity();
  end.translation() = Eigen::Vector3d(1.0, 0.0, 0.0);
  const integrators::SweepMotion motion = integrators::make_sweep_motion(begin, begin, end, 0, 0.1);
  EXPECT_FLOAT_EQ(motion.deskew(Vec3f(0, 0, 0), 0.3f).x, 1.0f);
  EXPECT_FLOAT_EQ(motion.deskew(Vec3f(0, 0, 0), -0.3f).x, 0.0f);
  EXPECT_FALSE(motion.deskew(Vec3f(0, 0, 0), NAN).is_finite());
  EXPECT_THROW(integrators::make_sweep_motion(begin, begin, end, 0.1, 0.1), Error);
  Eigen::Isometry3d broken = begin;
  broken.translation().x() = NAN;
  EXPECT_THROW(integrators::make_sweep_motion(begin, broken, end, 0.0, 0.1), Error);
}

// One sweep of a spinning LiDAR in a room: column c fires at c / columns of the sweep from the
// pose interpolated between `begin` (the stamp) and `end`; each point is in the sensor frame at
// its own firing time.
struct TimedScan {
  std::vector<Vec3f> points;
  std::vector<float> times_s;
  std::vector<Vec3f> points_at_stamp;  // the same points moved to `begin` on the host (double)
};
constexpr double kSweepS = 0.1;
TimedScan sweep_scan(const AnalyticScene& scene, const Eigen::Isometry3d& begin,
                     const Eigen::Isometry3d& end, int columns, int rows) {
  TimedScan scan;
  for (int c = 0; c < columns; ++c) {
    const double alpha = static_cast<double>(c) / columns;
    const Eigen::Isometry3d pose = interpolated(begin, end, alpha);
    // One column: rows beams at this azimuth, cast from this column's pose.
    for (int r = 0; r < rows; ++r) {
      const double elevation = (-0.5 + (r + 0.5) / rows) * 60.0 * M_PI / 180.0;
      const double azimuth = 2.0 * M_PI * c / columns;
      const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth),
                                      std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
      const double range = scene.intersect(pose.translation(), pose.linear() * direction);
      if (!(range < 9.0)) continue;
      const Eigen::Vector3d p = direction * range;
      const Eigen::Vector3d at_stamp = begin.inverse() * pose * p;
      scan.points.emplace_back(float(p.x()), float(p.y()), float(p.z()));
      scan.times_s.push_back(static_cast<float>(alpha * kSweepS));
      scan.points_at_stamp.emplace_back(float(at_stamp.x()), float(at_stamp.y()),
                                        float(at_stamp.z()));
    }
  }
  return scan;
}

AnalyticScene room() {
  AnalyticScene scene;
  scene.shape = testing_support::Shape::kBox;
  scene.center = Eigen::Vector3d(0.3, -0.2, 0.1);
  scene.half_extent = Eigen::Vector3d(3.0, 2.5, 2.0);
  return scene;
}

// A drone turning at 180 deg/s and flying at 3 m/s: 18 degrees and 0.3 m over the sweep, about
// 0.9 m at the room's far walls, several 0.1 m voxels.
void sweep_poses(Eigen::Isometry3d* begin, Eigen::Isometry3d* end) {
  *begin = Eigen::Isometry3d::Identity();
  begin->translation() = Eigen::Vector3d(-0.4, 0.2, 0.0);
  *end = *begin;
  end->translation() += Eigen::Vector3d(0.3, 0.0, 0.05);
  end->linear() =
      Eigen::AngleAxisd(18.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

integrators::TsdfIntegratorConfig room_config() {
  integrators::TsdfIntegratorConfig config;
  config.truncation_distance_m = 0.3f;
  config.max_ray_length_m = 10.0f;
  return config;
}

// RMS (m) of the map's distances against the room's over the observed voxels of the band.
double band_rmse_m(const map::TsdfMap& map, const AnalyticScene& scene, float truncation_m) {
  const int side = map.voxels_per_side();
  const double voxel = map.voxel_size_m();
  double squared = 0.0;
  int64_t count = 0;
  for (const map::HostBlock& block : map.snapshot()) {
    for (int k = 0; k < side * side * side; ++k) {
      const map::TsdfVoxel& v = block.tsdf[k];
      if (!(v.weight > 0.0f) || std::abs(v.distance_m) >= 0.99f * truncation_m) continue;
      const Eigen::Vector3d centre = (Eigen::Vector3d(block.index.x * side + k % side,
                                                      block.index.y * side + (k / side) % side,
                                                      block.index.z * side + k / (side * side)) +
                                      Eigen::Vector3d::Constant(0.5)) *
                                     voxel;
      const double truth =
          std::clamp(scene.signed_distance(centre), -double(truncation_m), double(truncation_m));
      squared += (v.distance_m - truth) * (v.distance_m - truth);
      ++count;
    }
  }
  return count ? std::sqrt(squared / count) : INFINITY;
}

// The scan's points and times uploaded to the map's device and integrated at `begin`, de-skewed
// by the sweep from `begin` to `end`.
integrators::IntegrationStats integrate_timed(const TimedScan& scan, const Eigen::Isometry3d& begin,
                                              const Eigen::Isometry3d& end, map::TsdfMap* map) {
  const Stream stream(map->device());
  Buffer<Vec3f> points(map->device());
  Buffer<float> times(map->device());
  points.copy_from_host(scan.points, stream);
  times.copy_from_host(scan.times_s, stream);
  integrators::PointCloudView view;
  view.points = points.data();
  view.count = static_cast<int64_t>(scan.points.size());
  view.times_s = times.data();
  view.sweep = integrators::make_sweep_motion(begin, begin, end, 0.0, kSweepS);
  const integrators::IntegrationStats stats =
      integrators::TsdfIntegrator(room_config()).integrate(*map, view, begin, stream);
  stream.synchronize();
  return stats;
}

class TsdfDeskewTest : public DeviceTest {};

TEST_P(TsdfDeskewTest, DeskewedSweepMapsLikeTheSamePointsMovedOnTheHost) {
  const AnalyticScene scene = room();
  Eigen::Isometry3d begin, end;
  sweep_poses(&begin, &end);
  const TimedScan scan = sweep_scan(scene, begin, end, 720, 32);
  const integrators::TsdfIntegratorConfig config = room_config();

  // De-skewed on the device, from the uploaded points and times.
  map::TsdfMap deskewed(device(), map::TsdfMapConfig{0.1f, 8, {}});
  const integrators::IntegrationStats stats = integrate_timed(scan, begin, end, &deskewed);
  EXPECT_EQ(stats.points_deskewed, static_cast<int64_t>(scan.points.size()));

  map::TsdfMap moved(device(), map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegrator(config).integrate(moved, scan.points_at_stamp, {}, begin);
  map::TsdfMap smeared(device(), map::TsdfMapConfig{0.1f, 8, {}});
  integrators::TsdfIntegrator(config).integrate(smeared, scan.points, {}, begin);

  const double deskewed_m = band_rmse_m(deskewed, scene, config.truncation_distance_m);
  const double moved_m = band_rmse_m(moved, scene, config.truncation_distance_m);
  const double smeared_m = band_rmse_m(smeared, scene, config.truncation_distance_m);
  EXPECT_NEAR(deskewed_m, moved_m, 0.02 * moved_m);
  EXPECT_LT(deskewed_m, 0.5 * smeared_m)
      << "de-skewed " << deskewed_m << " m, smeared " << smeared_m << " m";
  EXPECT_EQ(deskewed.block_count(), moved.block_count());
}
COVOX_INSTANTIATE_ON_ALL_DEVICES(TsdfDeskewTest);

TEST(TsdfDeskewParity, CpuAndCudaBuildTheSameDeskewedMap) {
  COVOX_SKIP_WITHOUT_GPU();
  const AnalyticScene scene = room();
  Eigen::Isometry3d begin, end;
  sweep_poses(&begin, &end);
  const TimedScan scan = sweep_scan(scene, begin, end, 720, 32);
  std::vector<std::vector<map::HostBlock>> snapshots;
  for (Device device : {Device::kCpu, Device::kCuda}) {
    map::TsdfMap map(device, map::TsdfMapConfig{0.1f, 8, {}});
    integrate_timed(scan, begin, end, &map);
    snapshots.push_back(map.snapshot());
  }
  ASSERT_EQ(snapshots[0].size(), snapshots[1].size());
  for (size_t b = 0; b < snapshots[0].size(); ++b) {
    ASSERT_EQ(snapshots[0][b].index, snapshots[1][b].index);
    for (size_t v = 0; v < snapshots[0][b].tsdf.size(); ++v) {
      ASSERT_NEAR(snapshots[0][b].tsdf[v].distance_m, snapshots[1][b].tsdf[v].distance_m, 1e-4f);
      ASSERT_NEAR(snapshots[0][b].tsdf[v].weight, snapshots[1][b].tsdf[v].weight,
                  2e-4f * std::max(1.0f, snapshots[0][b].tsdf[v].weight));
    }
  }
}

}  // namespace
}  // namespace covox

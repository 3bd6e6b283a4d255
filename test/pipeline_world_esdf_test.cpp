// SlamSystem's ESDF for planners, on both backends: query_esdf_world() at points of the world
// frame and esdf_voxels_world() (the 3-D ESDF near surfaces), checked against the exact distance
// of a hollow sphere that a LiDAR scans from inside, over several overlapping submaps; unobserved
// points are flagged, and a bounded voxel list keeps the smallest distances.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "covoxslam/pipeline/slam_system.h"
#include "support/analytic_scene.h"
#include "support/small_slam_config.h"
#include "support/test_devices.h"

namespace covox {
namespace pipeline {
namespace {

constexpr double kRadius_m = 4.0;
constexpr double kVoxel_m = 0.2;    // small_slam_config()
constexpr double kEsdfMax_m = 1.0;  // small_slam_config()'s esdf_max_distance_m

testing_support::AnalyticScene sphere() {
  testing_support::AnalyticScene scene;
  scene.shape = testing_support::Shape::kSphere;
  scene.radius = kRadius_m;
  return scene;
}

class WorldEsdf : public testing_support::DeviceTest {
 protected:
  // 16 scans while the sensor moves 1.5 m along x and turns: 4 submaps (one per second), which
  // overlap everywhere.
  void SetUp() override {
    DeviceTest::SetUp();
    if (IsSkipped()) return;
    SlamConfig config = testing_support::small_slam_config();
    config.device = device();
    slam_ = std::make_unique<SlamSystem>(config);
    for (int k = 0; k < 16; ++k) {
      Scan scan;
      scan.stamp_s = 0.25 * k;
      scan.T_odom_sensor.linear() =
          Eigen::AngleAxisd(0.2 * k, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      scan.T_odom_sensor.translation() = Eigen::Vector3d(0.1 * k - 0.75, 0.0, 0.0);
      scan.points_sensor_m =
          testing_support::simulate_lidar(sphere(), scan.T_odom_sensor, 128, 16, 40.0, 10.0);
      ASSERT_TRUE(slam_->add_scan(std::move(scan)));
    }
    slam_->finish();
    ASSERT_GE(slam_->submaps().size(), 3u);
  }

  std::unique_ptr<SlamSystem> slam_;
};

// Points near the equator (inside the LiDAR's +-20 degree fan) at `radius_m`, every 5 degrees.
std::vector<Vec3f> ring(double radius_m, double z_m) {
  std::vector<Vec3f> points;
  for (int a = 0; a < 72; ++a) {
    const double angle = a * 5.0 * M_PI / 180.0;
    points.emplace_back(static_cast<float>(radius_m * std::cos(angle)),
                        static_cast<float>(radius_m * std::sin(angle)), static_cast<float>(z_m));
  }
  return points;
}

TEST_P(WorldEsdf, DistancesAndGradientsMatchTheSphere) {
  int compared = 0, within_voxel = 0, gradients_right = 0, gradients_compared = 0;
  for (double radius_m : {3.2, 3.4, 3.6, 3.8}) {
    const std::vector<Vec3f> points = ring(radius_m, 0.1);
    const std::vector<integrators::EsdfSample> samples = slam_->query_esdf_world(points);
    ASSERT_EQ(samples.size(), points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d p(points[i].x, points[i].y, points[i].z);
      const double truth = sphere().signed_distance(p);
      ASSERT_LT(truth, kEsdfMax_m);
      ++compared;
      if (!samples[i].valid) continue;
      if (std::abs(samples[i].distance_m - truth) <= kVoxel_m) ++within_voxel;
      // The distance grows away from the wall: towards the centre.
      const Eigen::Vector3d gradient(samples[i].gradient.x, samples[i].gradient.y,
                                     samples[i].gradient.z);
      if (truth > 0.3 && gradient.norm() > 0.1) {
        ++gradients_compared;
        if (gradient.normalized().dot(-p.normalized()) > 0.8) ++gradients_right;
      }
    }
  }
  // Re-gridding moves a turned submap's voxel by up to half a cell diagonal (0.17 m), so a few
  // more differ by over a voxel than in the samples above.
  EXPECT_GE(within_voxel, 0.85 * compared) << within_voxel << " of " << compared;
  EXPECT_GE(gradients_compared, 0.5 * compared);
  EXPECT_GE(gradients_right, 0.9 * gradients_compared)
      << gradients_right << " of " << gradients_compared;
}

TEST_P(WorldEsdf, UnobservedPointsAreFlagged) {
  // Beyond the wall and its truncation band, and far above the LiDAR's fan: never observed.
  std::vector<Vec3f> points = ring(kRadius_m + 2.0, 0.0);
  points.emplace_back(0.0f, 0.0f, 30.0f);
  for (const integrators::EsdfSample& sample : slam_->query_esdf_world(points))
    EXPECT_EQ(sample.valid, 0);
  EXPECT_TRUE(slam_->query_esdf_world({}).empty());
}

TEST_P(WorldEsdf, VoxelsNearSurfacesMatchTheSphereAndTheBoundKeepsTheNearest) {
  bool truncated = true;
  const std::vector<integrators::SlicePoint> voxels =
      slam_->esdf_voxels_world(0.5, 10000000, &truncated);
  EXPECT_FALSE(truncated);
  ASSERT_GT(voxels.size(), 1000u);
  size_t within_voxel = 0, compared = 0;
  for (const integrators::SlicePoint& voxel : voxels) {
    EXPECT_LE(voxel.distance_m, 0.5f);
    const Eigen::Vector3d p(voxel.position_m.x, voxel.position_m.y, voxel.position_m.z);
    // Cells are world-aligned: their centres sit at (i + 0.5) voxels.
    for (int axis = 0; axis < 3; ++axis) {
      const double cells = p[axis] / kVoxel_m - 0.5;
      EXPECT_NEAR(cells, std::round(cells), 1e-3) << p.transpose();
    }
    // Compared on the free side near the equator, where the nearest wall is inside the LiDAR's
    // fan (above and below it the nearest observed wall is farther than the true one), up to a
    // voxel less than the band (a voxel truly farther is listed only when it is underestimated).
    const double truth = sphere().signed_distance(p);
    if (std::abs(p.z()) > 0.6 || truth < 0.0 || truth > 0.5 - kVoxel_m) continue;
    ++compared;
    if (std::abs(voxel.distance_m - truth) <= kVoxel_m) ++within_voxel;
    // Overlapping submaps keep the smaller distance: never more clearance than there is.
    EXPECT_LE(voxel.distance_m, truth + kVoxel_m) << p.transpose();
  }
  ASSERT_GT(compared, 500u);
  // Re-gridding moves a turned submap's voxel by up to half a cell diagonal (0.17 m), so a few
  // more differ by over a voxel than in the samples above.
  EXPECT_GE(within_voxel, 0.85 * compared) << within_voxel << " of " << compared;

  const size_t bound = voxels.size() / 4;
  const std::vector<integrators::SlicePoint> bounded =
      slam_->esdf_voxels_world(0.5, bound, &truncated);
  EXPECT_TRUE(truncated);
  ASSERT_EQ(bounded.size(), bound);
  std::vector<float> distances;
  for (const integrators::SlicePoint& voxel : voxels) distances.push_back(voxel.distance_m);
  std::nth_element(distances.begin(), distances.begin() + bound, distances.end());
  for (const integrators::SlicePoint& voxel : bounded)
    EXPECT_LE(voxel.distance_m, distances[bound]);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(WorldEsdf);

}  // namespace
}  // namespace pipeline
}  // namespace covox

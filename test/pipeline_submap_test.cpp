// Submaps: the creation policy (time, distance, blocks) as a pure decision, the 4-DoF pose helpers
// the backend relies on, and one submap built from simulated scans and finished.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/map_integrators.h"
#include "covoxslam/pipeline/submap.h"
#include "support/analytic_scene.h"

namespace covox {
namespace pipeline {
namespace {

SubmapStatistics active_submap(int64_t scans, double start_stamp_s, double distance_m,
                               int64_t blocks) {
  SubmapStatistics statistics;
  statistics.scans = scans;
  statistics.start_stamp_s = start_stamp_s;
  statistics.end_stamp_s = start_stamp_s;
  statistics.distance_travelled_m = distance_m;
  statistics.blocks = blocks;
  return statistics;
}

// The TSDF and ESDF of every block, in snapshot order, as the bits of their numbers: equal when
// the two maps hold the same voxels bit for bit.
std::vector<uint32_t> voxel_bits(const map::TsdfMap& map) {
  std::vector<uint32_t> bits;
  const auto append = [&bits](float value) {
    uint32_t word = 0;
    std::memcpy(&word, &value, sizeof(word));
    bits.push_back(word);
  };
  for (const map::HostBlock& block : map.snapshot()) {
    bits.push_back(static_cast<uint32_t>(block.index.x));
    bits.push_back(static_cast<uint32_t>(block.index.y));
    bits.push_back(static_cast<uint32_t>(block.index.z));
    for (const map::TsdfVoxel& voxel : block.tsdf) {
      append(voxel.distance_m);
      append(voxel.weight);
    }
    for (const map::EsdfVoxel& voxel : block.esdf) {
      append(voxel.distance_m);
      bits.push_back(voxel.observed);
    }
  }
  return bits;
}

// A hollow sphere of radius 3 m around the origin and the settings its submaps are built with.
struct SphereSetting {
  SphereSetting() {
    scene.shape = testing_support::Shape::kSphere;
    scene.radius = 3.0;
    map.voxel_size_m = 0.2f;
    map.voxels_per_side = 8;
    tsdf.max_ray_length_m = 8.0f;
    esdf.esdf_max_distance_m = 1.0f;
  }
  std::unique_ptr<MapIntegrators> stage() const {
    return std::make_unique<MapIntegrators>(tsdf, esdf, integrators::MeshIntegratorConfig(),
                                            Stream(Device::kCpu));
  }
  // A simulated scan of the sphere from `pose` (`columns` x 16 beams) integrated into `submap`.
  void integrate_scan(Submap* submap, MapIntegrators* stage, const Eigen::Isometry3d& pose,
                      int columns, double stamp_s) const {
    const std::vector<Vec3f> points =
        testing_support::simulate_lidar(scene, pose, columns, 16, 60.0, 10.0);
    Buffer<Vec3f> device_points = Buffer<Vec3f>::from_host(Device::kCpu, points, stage->stream());
    integrators::PointCloudView view;
    view.points = device_points.data();
    view.count = static_cast<int64_t>(points.size());
    submap->integrate(*stage, view, pose, stamp_s);
  }

  testing_support::AnalyticScene scene;
  map::TsdfMapConfig map;
  integrators::TsdfIntegratorConfig tsdf;
  integrators::EsdfIntegratorConfig esdf;
};

TEST(PipelineSubmapPolicy, TimeIntervalEndsASubmapWhenTheIntervalHasPassed) {
  SubmapPolicyConfig config;
  config.policy = SubmapCreationPolicy::kTimeInterval;
  config.interval_s = 10.0;
  const SubmapStatistics active = active_submap(5, 100.0, 50.0, 5000);
  EXPECT_FALSE(should_start_new_submap(config, active, 109.99, 1.0));
  EXPECT_TRUE(should_start_new_submap(config, active, 110.0, 0.0));
  EXPECT_TRUE(should_start_new_submap(config, active, 125.0, 0.0));
}

TEST(PipelineSubmapPolicy, DistanceEndsASubmapWhenThePathReachesTheThreshold) {
  SubmapPolicyConfig config;
  config.policy = SubmapCreationPolicy::kDistanceTravelled;
  config.distance_m = 10.0;
  const SubmapStatistics active = active_submap(5, 0.0, 9.0, 5000);
  EXPECT_FALSE(should_start_new_submap(config, active, 1000.0, 0.5));  // time does not matter
  EXPECT_TRUE(should_start_new_submap(config, active, 1.0, 1.0));
}

TEST(PipelineSubmapPolicy, BlockCountEndsASubmapOnceItHasEnoughBlocks) {
  SubmapPolicyConfig config;
  config.policy = SubmapCreationPolicy::kBlockCount;
  config.max_blocks = 100;
  EXPECT_FALSE(should_start_new_submap(config, active_submap(5, 0.0, 100.0, 99), 1000.0, 100.0));
  EXPECT_TRUE(should_start_new_submap(config, active_submap(5, 0.0, 0.0, 100), 0.1, 0.0));
}

TEST(PipelineSubmapPolicy, AnEmptySubmapNeverEnds) {
  SubmapPolicyConfig config;
  config.policy = SubmapCreationPolicy::kBlockCount;
  config.max_blocks = 1;
  EXPECT_FALSE(should_start_new_submap(config, active_submap(0, 0.0, 0.0, 10), 100.0, 100.0));
}

TEST(PipelineSubmapPolicy, NamesParseAndBadValuesAreNamed) {
  EXPECT_EQ(parse_submap_creation_policy("blocks"), SubmapCreationPolicy::kBlockCount);
  EXPECT_EQ(parse_submap_creation_policy("time"), SubmapCreationPolicy::kTimeInterval);
  EXPECT_EQ(parse_submap_creation_policy("distance"), SubmapCreationPolicy::kDistanceTravelled);
  EXPECT_STREQ(to_string(SubmapCreationPolicy::kDistanceTravelled), "distance");
  EXPECT_THROW(parse_submap_creation_policy("hourly"), Error);
  SubmapPolicyConfig config;
  config.policy = SubmapCreationPolicy::kTimeInterval;
  config.interval_s = 0.0;
  try {
    validate(config);
    FAIL() << "expected covox::Error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("interval_s"), std::string::npos) << error.what();
  }
  config.policy = SubmapCreationPolicy::kBlockCount;
  config.max_blocks = 0;
  EXPECT_THROW(validate(config), Error);
}

TEST(PipelineSubmapPose, GravityAlignmentKeepsPositionAndHeadingOnly) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY()) *
                   Eigen::AngleAxisd(-0.05, Eigen::Vector3d::UnitX()))
                      .toRotationMatrix();
  pose.translation() = Eigen::Vector3d(1.0, -2.0, 3.0);
  const backend::Pose4Dof pose_4dof = pose_4dof_from_isometry(pose);
  EXPECT_NEAR(pose_4dof.yaw, 0.7, 1e-12);
  EXPECT_DOUBLE_EQ(pose_4dof.z, 3.0);
  const Eigen::Isometry3d aligned = gravity_aligned(pose);
  EXPECT_TRUE(aligned.translation().isApprox(pose.translation()));
  EXPECT_NEAR((aligned.linear() * Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitZ()).norm(), 0.0,
              1e-12);
}

TEST(PipelineSubmapPose, RelativePoseComposesBackToTheTarget) {
  const backend::Pose4Dof from{1.0, 2.0, 0.5, 3.0};
  const backend::Pose4Dof to{-4.0, 0.5, 1.5, -2.9};
  const backend::Pose4Dof relative = relative_pose_4dof(from, to);
  // to = from * relative, checked through the isometries.
  const Eigen::Isometry3d composed = to_isometry(from) * to_isometry(relative);
  EXPECT_TRUE(composed.isApprox(to_isometry(to), 1e-12));
  EXPECT_LT(std::abs(relative.yaw), 3.14159265358979323846 + 1e-12);  // wrapped
}

TEST(PipelineSubmapPose, BlendedCorrectionMovesLinearlyAndTurnsAboutTheVertical) {
  // A tilted sensor pose and two yaw + translation corrections 0.3 rad apart.
  Eigen::Isometry3d sensor = to_isometry(backend::Pose4Dof{3.0, -1.0, 2.0, 0.4});
  sensor.linear() = sensor.linear() * (Eigen::AngleAxisd(0.08, Eigen::Vector3d::UnitY()) *
                                       Eigen::AngleAxisd(-0.05, Eigen::Vector3d::UnitX()))
                                          .toRotationMatrix();
  const Eigen::Isometry3d C_from = to_isometry(backend::Pose4Dof{1.0, 2.0, 0.3, 0.2});
  const Eigen::Isometry3d C_to = to_isometry(backend::Pose4Dof{1.4, 1.0, 0.5, 0.5});
  const Eigen::Isometry3d A = C_from * sensor, B = C_to * sensor;
  // The ends are the two corrected poses, and alpha is clamped to them.
  EXPECT_TRUE(blend_corrected_pose(C_from, C_to, sensor, 0.0).isApprox(A, 1e-12));
  EXPECT_TRUE(blend_corrected_pose(C_from, C_to, sensor, 1.0).isApprox(B, 1e-12));
  EXPECT_TRUE(blend_corrected_pose(C_from, C_to, sensor, -0.5).isApprox(A, 1e-12));
  EXPECT_TRUE(blend_corrected_pose(C_from, C_to, sensor, 2.0).isApprox(B, 1e-12));
  // A quarter of the way: a quarter of the displacement and of the 0.3 rad turn, tilt unchanged.
  const Eigen::Isometry3d quarter = blend_corrected_pose(C_from, C_to, sensor, 0.25);
  EXPECT_LT((quarter.translation() - (A.translation() + 0.25 * (B.translation() - A.translation())))
                .norm(),
            1e-12);
  EXPECT_NEAR(pose_4dof_from_isometry(quarter).yaw, pose_4dof_from_isometry(A).yaw + 0.25 * 0.3,
              1e-12);
  const double tilt_a = std::acos((A.linear() * Eigen::Vector3d::UnitZ()).z());
  const double tilt_q = std::acos((quarter.linear() * Eigen::Vector3d::UnitZ()).z());
  EXPECT_NEAR(tilt_q, tilt_a, 1e-12);
  EXPECT_NEAR(
      (quarter.linear().transpose() * quarter.linear() - Eigen::Matrix3d::Identity()).norm(), 0.0,
      1e-12);
  // Corrections at +179 and -179 degrees are 2 degrees apart: half way turns by 1 degree, not 179.
  const double deg = 3.14159265358979323846 / 180.0;
  const Eigen::Isometry3d C_west = to_isometry(backend::Pose4Dof{0.0, 0.0, 0.0, 179.0 * deg});
  const Eigen::Isometry3d C_east = to_isometry(backend::Pose4Dof{0.0, 0.0, 0.0, -179.0 * deg});
  const Eigen::Isometry3d half = blend_corrected_pose(C_west, C_east, sensor, 0.5);
  const Eigen::Matrix3d turn = half.linear() * (C_west * sensor).linear().transpose();
  EXPECT_NEAR(std::atan2(turn(1, 0), turn(0, 0)), 1.0 * deg, 1e-9);
}

TEST(PipelineSubmapPose, InvalidPosesAreRecognised) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  EXPECT_TRUE(is_valid_rigid_pose(pose));
  pose.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(is_valid_rigid_pose(pose));
  pose = Eigen::Isometry3d::Identity();
  pose.linear() *= 2.0;  // a scale is not a rotation
  EXPECT_FALSE(is_valid_rigid_pose(pose));
}

TEST(PipelineSubmap, IntegratedScansAreCountedAndFinishingGivesMeshEsdfAndBox) {
  const SphereSetting setting;
  const std::unique_ptr<MapIntegrators> stage = setting.stage();
  Eigen::Isometry3d first = Eigen::Isometry3d::Identity();
  first.translation() = Eigen::Vector3d(0.5, 0.0, 0.0);
  first.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  Submap submap(7, Device::kCpu, setting.map, gravity_aligned(first));
  for (int k = 0; k < 3; ++k) {
    Eigen::Isometry3d pose = first;
    pose.translation().x() += 0.2 * k;
    setting.integrate_scan(&submap, stage.get(), pose, 64, 10.0 + k);
  }
  EXPECT_EQ(submap.id(), 7);
  EXPECT_EQ(submap.statistics().scans, 3);
  EXPECT_DOUBLE_EQ(submap.statistics().start_stamp_s, 10.0);
  EXPECT_DOUBLE_EQ(submap.statistics().end_stamp_s, 12.0);
  EXPECT_NEAR(submap.statistics().distance_travelled_m, 0.4, 1e-9);
  EXPECT_GT(submap.statistics().blocks, 0);
  EXPECT_FALSE(submap.finished());
  EXPECT_TRUE(submap.bounding_box_submap().isEmpty());

  submap.finish(*stage);
  EXPECT_TRUE(submap.finished());
  EXPECT_GT(submap.mesh().triangle_count(), 100u);
  // The sphere (radius 3 around the world origin) lies inside the world box, and the box is
  // not much larger than the sphere plus a block of margin.
  const Eigen::AlignedBox3d box = submap.bounding_box_world();
  EXPECT_TRUE(box.contains(Eigen::Vector3d(2.9, 0.0, 0.0)));
  EXPECT_TRUE(box.contains(Eigen::Vector3d(-2.9, 0.0, 0.0)));
  EXPECT_LT(box.sizes().maxCoeff(),
            2 * 3.0 + 4 * setting.map.voxel_size_m * setting.map.voxels_per_side);
  // Some ESDF voxel got a finite, non-clamped distance.
  bool esdf_written = false;
  for (const map::HostBlock& block : submap.map().snapshot()) {
    for (const map::EsdfVoxel& voxel : block.esdf) {
      if (voxel.observed && std::abs(voxel.distance_m) > 0.1f && std::abs(voxel.distance_m) < 0.9f)
        esdf_written = true;
    }
  }
  EXPECT_TRUE(esdf_written);
  // A finished submap is frozen.
  Buffer<Vec3f> one(Device::kCpu, 1);
  integrators::PointCloudView view;
  view.points = one.data();
  view.count = 0;
  EXPECT_THROW(submap.integrate(*stage, view, first, 20.0), Error);
}

// SlamSystem builds every submap with one integration stage per thread. Two submaps built in turn
// by one stage (its scratch memory sized by the larger scans, then reused for the smaller ones)
// hold the same voxels and meshes, bit for bit, as the same submaps built each by a stage of its
// own: a stage carries nothing from one map into the next.
TEST(PipelineSubmap, SubmapsSharingOneStageEqualSubmapsWithStagesOfTheirOwn) {
  const SphereSetting setting;
  const std::unique_ptr<MapIntegrators> shared = setting.stage();
  const std::unique_ptr<MapIntegrators> own[2] = {setting.stage(), setting.stage()};

  // Submap 0 from fine scans near the centre, submap 1 from coarse ones 1.5 m off.
  const int columns[2] = {64, 24};
  Eigen::Isometry3d origins[2] = {Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity()};
  origins[1].translation() = Eigen::Vector3d(1.5, -0.5, 0.2);
  std::vector<std::unique_ptr<Submap>> by_shared, by_own;
  for (int s = 0; s < 2; ++s) {
    by_shared.push_back(std::make_unique<Submap>(s, Device::kCpu, setting.map, origins[s]));
    by_own.push_back(std::make_unique<Submap>(s, Device::kCpu, setting.map, origins[s]));
  }
  for (int k = 0; k < 3; ++k) {
    for (int s = 0; s < 2; ++s) {
      Eigen::Isometry3d pose = origins[s];
      pose.translation().y() += 0.25 * k;
      setting.integrate_scan(by_shared[s].get(), shared.get(), pose, columns[s], k);
      setting.integrate_scan(by_own[s].get(), own[s].get(), pose, columns[s], k);
    }
  }
  for (int s = 0; s < 2; ++s) {
    by_shared[s]->finish(*shared);
    by_own[s]->finish(*own[s]);
  }
  for (int s = 0; s < 2; ++s) {
    SCOPED_TRACE("submap " + std::to_string(s));
    EXPECT_GT(by_own[s]->mesh_triangles(), 100);
    EXPECT_EQ(voxel_bits(by_shared[s]->map()), voxel_bits(by_own[s]->map()));
    const map::Mesh& a = by_shared[s]->mesh();
    const map::Mesh& b = by_own[s]->mesh();
    EXPECT_EQ(a.triangles, b.triangles);
    ASSERT_EQ(a.vertices_m.size(), b.vertices_m.size());
    EXPECT_EQ(0, std::memcmp(a.vertices_m.data(), b.vertices_m.data(),
                             a.vertices_m.size() * sizeof(Vec3f)));
  }
  // The two submaps differ, so the comparison above could tell them apart.
  EXPECT_NE(voxel_bits(by_own[0]->map()), voxel_bits(by_own[1]->map()));
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

// Top-view wall maps and the revisit start from the walls (pipeline/wall_map.h): distances
// against brute force, a known offset recovered from a partial view, the room's walls found from
// its TSDF, the cache built again after a release, and a registration that starts 1.5 m off
// ending at the truth when the walls give its start.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/registration_constraints.h"
#include "covoxslam/pipeline/wall_map.h"
#include "support/registration_room.h"
#include "support/test_devices.h"

namespace covox {
namespace pipeline {
namespace {

using backend::Pose4Dof;
using testing_support::DeviceTest;
using testing_support::kDegToRad;

// Wall columns along a segment, every `step_m`.
void add_segment(std::vector<Eigen::Vector2d>* columns, Eigen::Vector2d a, Eigen::Vector2d b,
                 double step_m = 0.1) {
  const int n = static_cast<int>(std::ceil((b - a).norm() / step_m));
  for (int k = 0; k <= n; ++k) columns->push_back(a + (b - a) * (static_cast<double>(k) / n));
}

// An irregular yard: walls of different lengths and a few posts, so no shift matches it to itself.
std::vector<Eigen::Vector2d> yard() {
  std::vector<Eigen::Vector2d> columns;
  add_segment(&columns, {-6.0, -4.0}, {7.0, -4.0});
  add_segment(&columns, {7.0, -4.0}, {7.0, 2.5});
  add_segment(&columns, {-6.0, -4.0}, {-6.0, 5.0});
  add_segment(&columns, {-6.0, 5.0}, {1.5, 5.0});
  add_segment(&columns, {-2.0, -1.0}, {1.0, 1.5});
  for (const Eigen::Vector2d& post :
       {Eigen::Vector2d(3.0, 0.5), Eigen::Vector2d(4.2, 3.1), Eigen::Vector2d(-4.0, 2.0)}) {
    columns.push_back(post);
  }
  return columns;
}

TEST(WallMap, DistancesMatchBruteForceAndStopAtTheCap) {
  const double cell = 0.2, cap = 1.0;
  std::mt19937 random(5);
  std::uniform_real_distribution<double> coordinate(-8.0, 8.0);
  std::vector<Eigen::Vector2d> columns;
  for (int k = 0; k < 40; ++k) columns.emplace_back(coordinate(random), coordinate(random));
  const WallMap wall = WallMap::from_columns(columns, cell, cap);
  // The map works on cells: distances from the query's cell centre to the columns' cell centres.
  auto centre = [&](double v) { return (std::floor(v / cell) + 0.5) * cell; };
  for (int q = 0; q < 2000; ++q) {
    const double x = coordinate(random), y = coordinate(random);
    double nearest = 1e9;
    for (const Eigen::Vector2d& c : columns)
      nearest = std::min(nearest, std::hypot(centre(x) - centre(c.x()), centre(y) - centre(c.y())));
    const double expected = nearest <= cap ? nearest : cap;
    ASSERT_NEAR(wall.distance_m(x, y), expected, 1e-6) << x << " " << y;
  }
  EXPECT_DOUBLE_EQ(wall.distance_m(1e6, 0.0), cap);  // outside the grid
  EXPECT_THROW(WallMap::from_columns(columns, 0.0, cap), Error);
}

TEST(WallMap, SearchRecoversAKnownOffsetFromAPartialView) {
  const std::vector<Eigen::Vector2d> fixed_columns = yard();
  // The moving submap saw part of the yard (x < 3 m) and a wall the fixed one did not, and sits
  // at T_fixed_moving = (1.3, -0.8, 2 degrees); its columns are in its own frame.
  const Pose4Dof truth{1.3, -0.8, 0.0, 2.0 * kDegToRad};
  const Eigen::Rotation2Dd R(truth.yaw);
  std::vector<Eigen::Vector2d> moving_columns;
  std::vector<Eigen::Vector2d> seen;
  for (const Eigen::Vector2d& f : fixed_columns) {
    if (f.x() < 3.0) seen.push_back(f);
  }
  add_segment(&seen, {-3.0, 8.0}, {2.0, 8.0});
  for (const Eigen::Vector2d& f : seen)
    moving_columns.push_back(R.inverse() * (f - Eigen::Vector2d(truth.x, truth.y)));
  const WallMap fixed = WallMap::from_columns(fixed_columns, 0.2, 1.0);
  const WallMap moving = WallMap::from_columns(moving_columns, 0.2, 1.0);
  const WallSearchConfig config;  // +-2.5 m, 0.1 m, +-3 degrees, 0.5 degrees
  const WallMatch match = match_walls(moving, fixed, Pose4Dof{}, config);
  std::printf("[ walls    ] found (%.2f, %.2f, %.2f deg), score %.1f of %zu columns\n",
              match.T_fixed_moving.x, match.T_fixed_moving.y, match.T_fixed_moving.yaw / kDegToRad,
              match.score, moving.columns().size());
  EXPECT_NEAR(match.T_fixed_moving.x, truth.x, 0.1 + 1e-9);
  EXPECT_NEAR(match.T_fixed_moving.y, truth.y, 0.1 + 1e-9);
  EXPECT_NEAR(match.T_fixed_moving.yaw, truth.yaw, 0.5 * kDegToRad + 1e-9);
  EXPECT_GT(match.score, 0.5 * static_cast<double>(moving.columns().size()) * 0.8);
  // Deterministic, and the guess's z is kept.
  const WallMatch again = match_walls(moving, fixed, Pose4Dof{0.0, 0.0, 0.7, 0.0}, config);
  EXPECT_EQ(again.T_fixed_moving.x, match.T_fixed_moving.x);
  EXPECT_EQ(again.T_fixed_moving.y, match.T_fixed_moving.y);
  EXPECT_EQ(again.T_fixed_moving.yaw, match.T_fixed_moving.yaw);
  EXPECT_EQ(again.score, match.score);
  EXPECT_EQ(again.T_fixed_moving.z, 0.7);
}

// The score of one pose evaluated on its own: every moving column turned and moved, its distance
// looked up and scored.
double direct_score(const WallMap& moving, const WallMap& fixed, double x, double y, double yaw,
                    double sigma_m) {
  const double c = std::cos(yaw), s = std::sin(yaw);
  double score = 0.0;
  for (const Eigen::Vector2d& column : moving.columns()) {
    const double px = c * column.x() - s * column.y(), py = s * column.x() + c * column.y();
    const double d = fixed.distance_m(px + x, py + y);
    if (d < 3.0 * sigma_m) score += std::exp(-d * d / (2.0 * sigma_m * sigma_m));
  }
  return score;
}

class WallMapTest : public DeviceTest {};

TEST_P(WallMapTest, SearchReturnsTheBestPoseOfAPoseByPoseEvaluation) {
  // Moving columns scattered beyond the fixed map's edges, a guess away from the origin: the
  // search's best score and pose are those of scoring every grid pose on its own, and the device's
  // sums are the host's to the bit.
  std::mt19937 random(11);
  std::uniform_real_distribution<double> coordinate(-9.0, 9.0);
  std::vector<Eigen::Vector2d> moving_columns;
  for (int k = 0; k < 300; ++k) moving_columns.emplace_back(coordinate(random), coordinate(random));
  const WallMap fixed = WallMap::from_columns(yard(), 0.2, 1.0);
  const WallMap moving = WallMap::from_columns(moving_columns, 0.2, 1.0);
  WallSearchConfig config;
  config.range_m = 1.0;
  config.yaw_range_rad = 2.0 * kDegToRad;
  config.yaw_step_rad = 1.0 * kDegToRad;
  const Pose4Dof guess{0.7, -1.3, 0.0, 5.0 * kDegToRad};
  const WallMatch match = match_walls(moving, fixed, guess, config, Stream(device()));
  const WallMatch on_host = match_walls(moving, fixed, guess, config, Stream(Device::kCpu));
  EXPECT_EQ(match.score, on_host.score);
  EXPECT_EQ(match.T_fixed_moving.x, on_host.T_fixed_moving.x);
  EXPECT_EQ(match.T_fixed_moving.y, on_host.T_fixed_moving.y);
  EXPECT_EQ(match.T_fixed_moving.yaw, on_host.T_fixed_moving.yaw);
  double best = -1.0;
  Pose4Dof best_pose;
  for (int a = -2; a <= 2; ++a) {
    for (int cy = -10; cy <= 10; ++cy) {
      for (int cx = -10; cx <= 10; ++cx) {
        const Pose4Dof pose{guess.x + cx * config.step_m, guess.y + cy * config.step_m, 0.0,
                            guess.yaw + a * config.yaw_step_rad};
        const double score = direct_score(moving, fixed, pose.x, pose.y, pose.yaw, config.sigma_m);
        if (score > best) {
          best = score;
          best_pose = pose;
        }
      }
    }
  }
  ASSERT_GT(best, 1.0);
  EXPECT_NEAR(match.score, best, 1e-9 * best);
  EXPECT_NEAR(match.T_fixed_moving.x, best_pose.x, 1e-12);
  EXPECT_NEAR(match.T_fixed_moving.y, best_pose.y, 1e-12);
  EXPECT_NEAR(match.T_fixed_moving.yaw, best_pose.yaw, 1e-12);
}

TEST_P(WallMapTest, TheRoomsWallsAreItsWallColumns) {
  const testing_support::AnalyticScene room = testing_support::registration_room();
  const std::unique_ptr<map::TsdfMap> map =
      testing_support::scan_room_submap(device(), room, Pose4Dof{}, 0.1f);
  const WallMap wall = WallMap::from_map(*map, 1.0, Stream(device()));
  ASSERT_GT(wall.columns().size(), 100u);
  int64_t near_a_wall = 0, far_from_walls = 0;
  for (const Eigen::Vector2d& c : wall.columns()) {
    const double dx = std::abs(std::abs(c.x() - room.center.x()) - room.half_extent.x());
    const double dy = std::abs(std::abs(c.y() - room.center.y()) - room.half_extent.y());
    near_a_wall += std::min(dx, dy) <= 0.25;
    far_from_walls += std::min(dx, dy) > 0.6;
  }
  // Floor and ceiling voxels have vertical gradients: they are not wall columns, except where the
  // floor is seen at grazing angles and the ray-built TSDF's gradient tilts (measured: 93 % of the
  // columns within 0.25 m of a wall, 3 % further than 0.6 m; the band within 0.25 m of the walls
  // is a third of the floor).
  EXPECT_GE(near_a_wall, static_cast<int64_t>(0.85 * wall.columns().size()));
  EXPECT_LE(far_from_walls, static_cast<int64_t>(0.05 * wall.columns().size()));
  std::printf(
      "[ walls    ] %zu wall columns, %lld within 0.25 m of a wall, %lld further than 0.6 m\n",
      wall.columns().size(), static_cast<long long>(near_a_wall),
      static_cast<long long>(far_from_walls));
}

// The cache keeps the first map's walls until release() (a compaction), then builds them from the
// map it is given next: the voxels brought back.
TEST_P(WallMapTest, TheCacheBuildsAgainAfterARelease) {
  const testing_support::AnalyticScene room = testing_support::registration_room();
  const std::unique_ptr<map::TsdfMap> first =
      testing_support::scan_room_submap(device(), room, Pose4Dof{}, 0.1f);
  const std::unique_ptr<map::TsdfMap> moved =
      testing_support::scan_room_submap(device(), room, Pose4Dof{0.6, -0.4, 0.0, 0.0}, 0.1f);
  const Stream stream(device());
  const WallMap first_walls = WallMap::from_map(*first, WallMapCache::kCapM, stream);
  const WallMap moved_walls = WallMap::from_map(*moved, WallMapCache::kCapM, stream);
  ASSERT_NE(first_walls.columns(), moved_walls.columns());
  WallMapCache cache;
  EXPECT_FALSE(cache.holds_walls());
  EXPECT_EQ(cache.get(*first, stream).columns(), first_walls.columns());
  EXPECT_EQ(cache.get(*moved, stream).columns(), first_walls.columns());  // kept
  EXPECT_TRUE(cache.holds_walls());
  cache.release();
  EXPECT_FALSE(cache.holds_walls());
  EXPECT_EQ(cache.get(*moved, stream).columns(), moved_walls.columns());
}

TEST_P(WallMapTest, ARevisitStartedFromTheWallsEndsAtTheTruth) {
  const testing_support::AnalyticScene room = testing_support::registration_room();
  const Pose4Dof T_W_Sj{0.0, 0.0, 0.0, 0.0};
  const Pose4Dof T_W_Si{0.6, -0.4, 0.05, 4.0 * kDegToRad};
  const std::unique_ptr<map::TsdfMap> map_j =
      testing_support::scan_room_submap(device(), room, T_W_Sj, 0.1f);
  const std::unique_ptr<map::TsdfMap> map_i =
      testing_support::scan_room_submap(device(), room, T_W_Si, 0.1f);
  SubmapRegistrationConfig config;
  config.revisits.wall_search = true;
  config.revisits.wall_search_min_score = 30.0;
  config.acceptance.max_correction_m = 3.0;
  config.sampling.ratio = 0.25f;
  // The one-way fine aligner alone, so the wall match is what brings the alignment home.
  config.alignment.symmetric = false;
  config.alignment.coarse_levels = 0;
  const Stream stream(device());
  const std::unique_ptr<SubmapRegistrationPoints> points =
      prepare_registration_points(*map_i, config, stream);
  RegistrationPartner partner;
  partner.id = 0;
  partner.map = map_j.get();
  partner.pose = T_W_Sj;
  const std::vector<RegistrationPartner> earlier{partner};
  // The guess is 1.5 m and 2 degrees off the truth (ids 0 and 10: a revisit).
  const Pose4Dof guess{T_W_Si.x - 1.2, T_W_Si.y + 0.9, T_W_Si.z, T_W_Si.yaw - 2.0 * kDegToRad};
  RegistrationCounts counts;
  const std::vector<SubmapConstraint> constraints =
      registration_constraints(10, *map_i, *points, guess, earlier, config, stream, &counts);
  ASSERT_EQ(constraints.size(), 1u);
  const Pose4Dof& m = constraints[0].measurement;
  std::printf("[ walls    ] measured (%.3f, %.3f, %.2f deg), true (%.3f, %.3f, %.2f deg)\n", m.x,
              m.y, m.yaw / kDegToRad, T_W_Si.x, T_W_Si.y, T_W_Si.yaw / kDegToRad);
  EXPECT_EQ(counts.started_from_walls, 1);
  EXPECT_LT(std::hypot(m.x - T_W_Si.x, m.y - T_W_Si.y), 0.05);
  EXPECT_LT(std::abs(m.yaw - T_W_Si.yaw), 0.5 * kDegToRad);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(WallMapTest);

}  // namespace
}  // namespace pipeline
}  // namespace covox

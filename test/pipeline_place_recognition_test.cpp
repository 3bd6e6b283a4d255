// Place recognition (pipeline/place_recognition.h): the surface columns against a host scan of
// the voxels and across backends, the descriptor's yaw and the bird's-eye translation on a known
// motion, the ring-key index against brute force, and a revisit whose estimate is metres and tens
// of degrees off closed from the descriptors alone.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <utility>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/map_integrators.h"
#include "covoxslam/pipeline/place_recognition.h"
#include "covoxslam/pipeline/registration_constraints.h"
#include "covoxslam/pipeline/submap.h"
#include "pipeline_test_scene.h"
#include "support/registration_room.h"
#include "support/test_devices.h"

namespace covox {
namespace pipeline {
namespace {

using backend::Pose4Dof;
using testing_support::DeviceTest;
using testing_support::kDegToRad;

// The surface columns by a plain walk over the host copy of every block: (x, y) -> (lowest,
// highest) layer of a voxel with weight > 0 and |distance| < band.
std::map<std::pair<int32_t, int32_t>, std::pair<int32_t, int32_t>> host_columns(
    const map::TsdfMap& map, float band_m) {
  std::map<std::pair<int32_t, int32_t>, std::pair<int32_t, int32_t>> columns;
  const int side = map.voxels_per_side();
  for (const map::HostBlock& block : map.snapshot()) {
    for (int z = 0; z < side; ++z) {
      for (int y = 0; y < side; ++y) {
        for (int x = 0; x < side; ++x) {
          const map::TsdfVoxel& v = block.tsdf[static_cast<size_t>(x + side * (y + side * z))];
          if (!(v.weight > 0.0f) || !(std::abs(v.distance_m) < band_m)) continue;
          const std::pair<int32_t, int32_t> key(block.index.x * side + x, block.index.y * side + y);
          const int32_t layer = block.index.z * side + z;
          auto found = columns.find(key);
          if (found == columns.end()) {
            columns[key] = {layer, layer};
          } else {
            found->second.first = std::min(found->second.first, layer);
            found->second.second = std::max(found->second.second, layer);
          }
        }
      }
    }
  }
  return columns;
}

class PlaceRecognitionTest : public DeviceTest {};

TEST_P(PlaceRecognitionTest, SurfaceColumnsAreTheVoxelsSurfaceColumns) {
  const testing_support::AnalyticScene room = testing_support::registration_room();
  const std::unique_ptr<map::TsdfMap> map =
      testing_support::scan_room_submap(device(), room, Pose4Dof{0.3, -0.2, 0.0, 0.2}, 0.1f);
  const float band_m = map->voxel_size_m();
  const std::vector<SurfaceColumn> columns = surface_columns(*map, band_m, Stream(device()));
  const auto expected = host_columns(*map, band_m);
  ASSERT_GT(expected.size(), 1000u);
  ASSERT_EQ(columns.size(), expected.size());
  const double voxel_m = map->voxel_size_m();
  size_t k = 0;
  for (const auto& [key, span] : expected) {  // both in (x, y) order
    const SurfaceColumn& c = columns[k++];
    EXPECT_DOUBLE_EQ(c.x_m, (key.first + 0.5) * voxel_m);
    EXPECT_DOUBLE_EQ(c.y_m, (key.second + 0.5) * voxel_m);
    EXPECT_DOUBLE_EQ(c.bottom_m, (span.first + 0.5) * voxel_m);
    EXPECT_DOUBLE_EQ(c.top_m, (span.second + 0.5) * voxel_m);
  }
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(PlaceRecognitionTest);

TEST(PlaceRecognitionParity, CpuAndCudaGiveTheSameColumns) {
  std::string message;
  if (!testing_support::require_gpu_or_skip_message(&message)) GTEST_SKIP() << message;
  const testing_support::AnalyticScene room = testing_support::registration_room();
  std::vector<SurfaceColumn> per_device[2];
  const Device devices[2] = {Device::kCpu, Device::kCuda};
  for (int d = 0; d < 2; ++d) {
    const std::unique_ptr<map::TsdfMap> map =
        testing_support::scan_room_submap(devices[d], room, Pose4Dof{}, 0.1f);
    per_device[d] = surface_columns(*map, map->voxel_size_m(), Stream(devices[d]));
  }
  ASSERT_EQ(per_device[0].size(), per_device[1].size());
  for (size_t k = 0; k < per_device[0].size(); ++k) {
    EXPECT_EQ(per_device[0][k].x_m, per_device[1][k].x_m);
    EXPECT_EQ(per_device[0][k].y_m, per_device[1][k].y_m);
    EXPECT_EQ(per_device[0][k].bottom_m, per_device[1][k].bottom_m);
    EXPECT_EQ(per_device[0][k].top_m, per_device[1][k].top_m);
  }
}

// An irregular yard of columns on a 0.2 m grid: walls of different heights, boxes and a floor.
std::vector<SurfaceColumn> yard_columns() {
  std::vector<SurfaceColumn> columns;
  auto box = [&](double x0, double y0, double x1, double y1, double height_m) {
    for (double x = x0; x <= x1; x += 0.2) {
      for (double y = y0; y <= y1; y += 0.2) columns.push_back(SurfaceColumn{x, y, 0.0, height_m});
    }
  };
  box(-14.0, -12.0, 14.0, 13.0, 0.0);  // the floor
  box(-14.0, 13.0, 10.0, 13.4, 3.0);
  box(-14.4, -12.0, -14.0, 13.0, 5.0);
  box(6.0, -12.4, 14.0, -12.0, 2.0);
  box(3.0, 2.0, 5.0, 6.5, 4.0);
  box(-6.0, -5.0, -4.5, -4.0, 1.5);
  box(9.0, 4.0, 9.6, 4.6, 6.0);
  return columns;
}

// The columns seen from a frame at `T_yard_frame` (their coordinates in that frame).
std::vector<SurfaceColumn> seen_from(const std::vector<SurfaceColumn>& columns,
                                     const Pose4Dof& T_yard_frame) {
  const double c = std::cos(T_yard_frame.yaw), s = std::sin(T_yard_frame.yaw);
  std::vector<SurfaceColumn> out;
  for (const SurfaceColumn& col : columns) {
    const double dx = col.x_m - T_yard_frame.x, dy = col.y_m - T_yard_frame.y;
    out.push_back(SurfaceColumn{c * dx + s * dy, -s * dx + c * dy, col.bottom_m, col.top_m});
  }
  return out;
}

TEST(PlaceDescriptor, ATurnIsASectorShiftAndTheBirdEyeFindsTheOffset) {
  PlaceRecognitionConfig config;
  const std::vector<SurfaceColumn> yard = yard_columns();
  const PlaceDescriptor fixed = place_descriptor(seen_from(yard, Pose4Dof{}), config);
  // Turned by 7 sectors of 6 degrees, in place: the same columns in shifted sectors.
  const double sector_rad = 2.0 * 3.14159265358979323846 / config.sectors;
  const Pose4Dof turned{0.0, 0.0, 0.0, 7.0 * sector_rad + 0.1 * sector_rad};
  const PlaceDescriptor moving = place_descriptor(seen_from(yard, turned), config);
  // The ring key does not see the turn, up to the columns that change sectors at the sectors'
  // edges: far nearer to the unturned key than to the key of the yard seen from elsewhere.
  const PlaceDescriptor elsewhere =
      place_descriptor(seen_from(yard, Pose4Dof{-8.0, 6.0, 0.0, 0.0}), config);
  double turned_sq = 0.0, elsewhere_sq = 0.0;
  for (size_t r = 0; r < fixed.ring_key.size(); ++r) {
    turned_sq += std::pow(moving.ring_key[r] - fixed.ring_key[r], 2.0);
    elsewhere_sq += std::pow(elsewhere.ring_key[r] - fixed.ring_key[r], 2.0);
  }
  EXPECT_LT(turned_sq, 0.1 * elsewhere_sq);
  const DescriptorMatch match = match_descriptors(moving, fixed);
  EXPECT_EQ(match.shift, 7);
  EXPECT_LT(match.distance, 0.1);
  EXPECT_NEAR(match.yaw_rad, 7.0 * sector_rad, 1e-9);
  // Moved as well: the polar shift may be lost, the bird's-eye correlation still finds the
  // offset to a cell (1 m) and the yaw to half a sector.
  const Pose4Dof moved{4.3, -2.6, 0.0, 40.0 * kDegToRad};
  const PlaceDescriptor far = place_descriptor(seen_from(yard, moved), config);
  const DescriptorMatch far_match = match_descriptors(far, fixed);
  const BirdEyeMatch overlap = match_bird_eye(far, fixed, far_match.yaw_rad, config);
  std::printf("[ place    ] distance %.3f, yaw %.1f deg; bird's-eye (%.2f, %.2f, %.1f deg) %.3f\n",
              far_match.distance, far_match.yaw_rad / kDegToRad, overlap.T_fixed_moving.x,
              overlap.T_fixed_moving.y, overlap.T_fixed_moving.yaw / kDegToRad, overlap.score);
  EXPECT_LT(std::hypot(overlap.T_fixed_moving.x - moved.x, overlap.T_fixed_moving.y - moved.y),
            1.0);
  EXPECT_LT(std::abs(overlap.T_fixed_moving.yaw - moved.yaw), 0.5 * sector_rad + 1e-9);
  EXPECT_GT(overlap.score, 0.5);
}

TEST(PlaceDescriptor, BirdEyeScoreIsOneForTheSameImageAndNeverAboveOne) {
  // Turned cells that land in one fixed cell count once: a score is a fraction of the smaller
  // image's total, 1 only where the images agree.
  PlaceRecognitionConfig config;
  const std::vector<SurfaceColumn> yard = yard_columns();
  const PlaceDescriptor fixed = place_descriptor(seen_from(yard, Pose4Dof{}), config);
  const BirdEyeMatch same = match_bird_eye(fixed, fixed, 0.0, config);
  EXPECT_DOUBLE_EQ(same.score, 1.0);
  EXPECT_EQ(same.T_fixed_moving.x, 0.0);
  EXPECT_EQ(same.T_fixed_moving.y, 0.0);
  EXPECT_EQ(same.T_fixed_moving.yaw, 0.0);
  for (double yaw_deg : {20.0, 45.0, 100.0, 225.0}) {
    const Pose4Dof pose{1.3, -0.7, 0.0, yaw_deg * kDegToRad};
    const PlaceDescriptor moving = place_descriptor(seen_from(yard, pose), config);
    const BirdEyeMatch match = match_bird_eye(moving, fixed, 0.0, config);
    EXPECT_LE(match.score, 1.0) << yaw_deg;
    EXPECT_GT(match.score, 0.5) << yaw_deg;
  }
}

TEST(PlaceDescriptor, PathAnchorsAreSpacedAlongThePathAndCapped) {
  std::vector<Eigen::Vector2d> path;
  for (int k = 0; k <= 50; ++k) path.emplace_back(0.2 * k, 0.0);  // 10 m in 0.2 m steps
  const std::vector<Eigen::Vector2d> anchors = path_anchors(path, 2.5);
  ASSERT_EQ(anchors.size(), 4u);  // 0, 2.6, 5.2, 7.8: the 0.2 m steps pass 2.5 m at 2.6 m
  EXPECT_EQ(anchors[0], path[0]);
  for (size_t k = 1; k < anchors.size(); ++k)
    EXPECT_NEAR(anchors[k].x() - anchors[k - 1].x(), 2.6, 1e-9);
  EXPECT_EQ(path_anchors(path, 0.0).size(), 1u);
  EXPECT_EQ(path_anchors({}, 2.5)[0], Eigen::Vector2d::Zero());
  const std::vector<Eigen::Vector2d> capped = path_anchors(path, 0.1);  // every point, thinned
  ASSERT_EQ(capped.size(), static_cast<size_t>(kMaxPathAnchors));
  EXPECT_EQ(capped.front(), path.front());
  EXPECT_EQ(capped.back(), path.back());
}

TEST(PlaceDescriptor, AnAnchorNearTheQueryGivesANearerRingKeyThanTheOrigin) {
  // Two passes through the yard whose submaps start 4 m apart along the same path: the ring key
  // about the second pass's origin is nearer to the first pass's anchor 4 m along its path than
  // to the first pass's origin.
  PlaceRecognitionConfig config;
  const std::vector<SurfaceColumn> yard = yard_columns();
  const std::vector<SurfaceColumn> first = seen_from(yard, Pose4Dof{-6.0, 0.0, 0.0, 0.0});
  const PlaceDescriptor second =
      place_descriptor(seen_from(yard, Pose4Dof{-2.0, 0.0, 0.0, 0.0}), config);
  auto key_distance_sq = [&](const PlaceDescriptor& d) {
    double sum = 0.0;
    for (size_t r = 0; r < d.ring_key.size(); ++r)
      sum += std::pow(d.ring_key[r] - second.ring_key[r], 2.0);
    return sum;
  };
  const double at_origin = key_distance_sq(place_descriptor(first, config));
  const double at_anchor =
      key_distance_sq(place_descriptor(first, config, Eigen::Vector2d(4.0, 0.0)));
  EXPECT_LT(at_anchor, 0.01 * at_origin);
}

TEST(RingKeyIndex, NearestKeysAreTheBruteForceOnes) {
  std::mt19937 random(7);
  std::uniform_real_distribution<float> uniform(0.0f, 3.0f);
  RingKeyIndex index;
  std::vector<std::vector<float>> keys;
  for (int64_t id = 0; id < 300; ++id) {
    std::vector<float> key(12);
    for (float& v : key) v = uniform(random);
    keys.push_back(key);
    index.add(id, key);
    if (id % 7 != 0) continue;
    // Queried after every 7th insertion, so both the tree and the unindexed tail answer.
    std::vector<float> query(12);
    for (float& v : query) v = uniform(random);
    const int64_t max_id = id - 5;
    std::vector<std::pair<double, int64_t>> brute;
    for (int64_t k = 0; k <= max_id; ++k) {
      double d = 0.0;
      for (size_t c = 0; c < query.size(); ++c) {
        const double e = static_cast<double>(query[c]) - keys[k][c];
        d += e * e;
      }
      brute.emplace_back(d, k);
    }
    std::sort(brute.begin(), brute.end());
    std::vector<int64_t> expected;
    for (size_t k = 0; k < std::min<size_t>(5, brute.size()); ++k)
      expected.push_back(brute[k].second);
    EXPECT_EQ(index.nearest(query, 5, max_id), expected) << "after id " << id;
  }
  EXPECT_THROW(index.add(1000, std::vector<float>(3)), Error);
}

// A submap of the yard (pipeline_test_scene.h: walls, pillars and crates without symmetry) from
// four scans around the true sensor pose `T_world_sensor`, in a submap frame whose odometry pose
// is `T_odom_world` times the truth.
std::unique_ptr<Submap> yard_submap(int64_t id, const sim::World& yard,
                                    const Eigen::Isometry3d& T_world_sensor,
                                    const Eigen::Isometry3d& T_odom_world, const Stream& stream) {
  const SlamConfig config = test_scene::yard_config();
  MapIntegrators integrators(config.tsdf, config.esdf, config.mesh, Stream(Device::kCpu));
  auto submap = std::make_unique<Submap>(id, Device::kCpu, config.map,
                                         gravity_aligned(T_odom_world * T_world_sensor));
  for (int k = 0; k < 4; ++k) {
    const Eigen::Isometry3d pose =
        T_world_sensor * test_scene::pose_4dof(0.4 * k, 0.0, 0.0, 0.15 * k);
    const std::vector<Vec3f> points =
        sim::simulate_scan(yard, test_scene::small_lidar(), pose, 100 * id + k);
    Buffer<Vec3f> device_points = Buffer<Vec3f>::from_host(Device::kCpu, points, stream);
    integrators::PointCloudView view;
    view.points = device_points.data();
    view.count = static_cast<int64_t>(points.size());
    submap->integrate(integrators, view, T_odom_world * pose, 0.1 * (10 * id + k));
  }
  submap->finish(integrators);
  return submap;
}

// Submap 10 revisits submap 0's place in the yard 1.5 m away, turned by 70 degrees; its odometry
// has drifted 9 m and 30 degrees, so the estimate shares no block with submap 0.
struct YardRevisit {
  explicit YardRevisit(const Stream& stream)
      : submap_0(yard_submap(0, yard, truth_0, Eigen::Isometry3d::Identity(), stream)),
        submap_10(yard_submap(10, yard, truth_10, drift, stream)),
        points_0(prepare_registration_points(submap_0->map(), registration, stream)),
        points_10(prepare_registration_points(submap_10->map(), registration, stream)) {}
  const sim::World yard = test_scene::make_yard();
  const Eigen::Isometry3d truth_0 = test_scene::pose_4dof(-2.0, 1.0, 1.5, 0.3);
  const Eigen::Isometry3d truth_10 = test_scene::pose_4dof(-1.0, -0.2, 1.5, 0.3 + 1.2217);
  const Eigen::Isometry3d drift = test_scene::pose_4dof(7.0, -5.5, 0.1, 30.0 * kDegToRad);
  const SubmapRegistrationConfig registration = test_scene::yard_config().registration;
  const std::unique_ptr<Submap> submap_0, submap_10;
  const std::unique_ptr<SubmapRegistrationPoints> points_0, points_10;
};

TEST(PlaceRecognizer, ClosesARevisitWhoseEstimateIsMetresAndDegreesOff) {
  const Stream stream(Device::kCpu);
  const YardRevisit revisit(stream);
  PlaceRecognitionConfig config;
  config.enabled = true;
  // The polar descriptor is around each submap's origin, and the origins are 1.5 m apart: here
  // it only ranks, the bird's-eye match and the registration decide.
  config.max_descriptor_distance = 1.0;
  PlaceRecognizer recognizer(config);
  PlaceRecognitionCounts counts;
  EXPECT_TRUE(recognizer.search(0, revisit.submap_0->map(), {}, {}, {}, stream, &counts).empty());
  const std::vector<RegistrationPartner> earlier{
      RegistrationPartner{0, &revisit.submap_0->map(), revisit.submap_0->pose(), nullptr,
                          revisit.points_0.get(), RegistrationOdometry()}};
  const std::vector<PlaceCandidate> candidates =
      recognizer.search(10, revisit.submap_10->map(), {}, {0}, {}, stream, &counts);
  ASSERT_EQ(candidates.size(), 1u);
  const std::vector<VerifiedClosure> verified =
      recognizer.verify(10, revisit.submap_10->map(), *revisit.points_10, revisit.submap_10->pose(),
                        candidates, earlier, revisit.registration, stream, nullptr, {}, &counts);
  std::printf(
      "[ place    ] candidates %lld, rejected: descriptor %lld, overlap %lld; verified "
      "%lld (too far %lld, too few points %lld, misfit %lld, failed %lld)\n",
      static_cast<long long>(counts.candidates), static_cast<long long>(counts.rejected_descriptor),
      static_cast<long long>(counts.rejected_overlap), static_cast<long long>(counts.verified),
      static_cast<long long>(counts.registration.rejected_too_far),
      static_cast<long long>(counts.registration.rejected_too_few_points),
      static_cast<long long>(counts.registration.rejected_misfit),
      static_cast<long long>(counts.registration.rejected_failed));
  EXPECT_EQ(counts.queries, 2);
  EXPECT_EQ(counts.candidates, 1);
  ASSERT_EQ(verified.size(), 1u);
  EXPECT_EQ(counts.registration.accepted, 1);
  // The true relative pose of the two submap frames (each the gravity-aligned first scan).
  const Pose4Dof expected = relative_pose_4dof(pose_4dof_from_isometry(revisit.truth_0),
                                               pose_4dof_from_isometry(revisit.truth_10));
  const SubmapConstraint& closure = verified[0].constraint;
  const Pose4Dof& m = closure.measurement;
  std::printf("[ place    ] measured (%.3f, %.3f, %.2f deg), true (%.3f, %.3f, %.2f deg)\n", m.x,
              m.y, m.yaw / kDegToRad, expected.x, expected.y, expected.yaw / kDegToRad);
  EXPECT_EQ(closure.from_submap, 0);
  EXPECT_EQ(closure.to_submap, 10);
  EXPECT_TRUE(closure.from_place_recognition);
  EXPECT_LT(std::hypot(m.x - expected.x, m.y - expected.y), 0.1);
  EXPECT_LT(std::abs(std::remainder(m.yaw - expected.yaw, 2.0 * test_scene::kPi)), 1.0 * kDegToRad);
  // Alone, the closure waits for a second one before it enters the graph.
  EXPECT_TRUE(recognizer.confirm(10, verified, &counts).empty());
  EXPECT_EQ(counts.accepted, 0);
  // A recent submap is never a candidate: for submap 11, only submap 0 is (10 is excluded).
  PlaceRecognitionCounts recent;
  recognizer.search(11, revisit.submap_10->map(), {}, {0, 10}, {}, stream, &recent);
  EXPECT_EQ(recent.candidates, 1);
}

TEST(PlaceRecognizer, AClosureTheOdometryCannotExplainIsRejected) {
  // The revisit of the test above: the right closure moves submap 10 about 9 m and 30 degrees
  // from where its odometry puts it. After 1000 m of path the odometry may have drifted that far
  // (2 % per metre: 20 m); after 50 m it cannot (1 m), so the same alignment is then rejected.
  const Stream stream(Device::kCpu);
  const YardRevisit revisit(stream);
  auto closures_after = [&](double path_m, PlaceRecognitionCounts* counts) {
    PlaceRecognitionConfig config;
    config.enabled = true;
    config.max_descriptor_distance = 1.0;
    PlaceRecognizer recognizer(config);
    RegistrationOdometry odometry_0, odometry_10;
    odometry_0.known = odometry_10.known = true;
    odometry_0.pose = revisit.submap_0->odometry_pose();
    odometry_10.pose = revisit.submap_10->odometry_pose();
    odometry_10.path_m = path_m;
    recognizer.search(0, revisit.submap_0->map(), {}, {}, {}, stream, counts);
    const std::vector<RegistrationPartner> earlier{
        RegistrationPartner{0, &revisit.submap_0->map(), revisit.submap_0->pose(), nullptr,
                            revisit.points_0.get(), odometry_0}};
    const std::vector<PlaceCandidate> candidates =
        recognizer.search(10, revisit.submap_10->map(), {}, {0}, {}, stream, counts);
    return recognizer.verify(10, revisit.submap_10->map(), *revisit.points_10,
                             revisit.submap_10->pose(), candidates, earlier, revisit.registration,
                             stream, nullptr, odometry_10, counts);
  };
  PlaceRecognitionCounts long_path, short_path;
  EXPECT_EQ(closures_after(1000.0, &long_path).size(), 1u);
  EXPECT_EQ(long_path.registration.rejected_by_odometry, 0);
  EXPECT_TRUE(closures_after(50.0, &short_path).empty());
  EXPECT_EQ(short_path.verified, 1);
  EXPECT_EQ(short_path.registration.rejected_by_odometry, 1);
}

// A closure from earlier submap `from` (true pose `truth_from`, odometry = truth) to new submap
// `to` (true pose `truth_to`; its odometry drifted by `drift` after `path_m`), measuring the true
// relative pose moved by `error`.
VerifiedClosure closure(int64_t from, const Pose4Dof& truth_from, int64_t to,
                        const Pose4Dof& truth_to, const Pose4Dof& drift, double path_m,
                        const Pose4Dof& error = Pose4Dof{}) {
  VerifiedClosure c;
  c.constraint.kind = SubmapConstraintKind::kRegistration;
  c.constraint.from_submap = from;
  c.constraint.to_submap = to;
  c.constraint.from_place_recognition = true;
  c.constraint.measurement = compose(relative_pose_4dof(truth_from, truth_to), error);
  c.earlier_odometry.known = c.new_odometry.known = true;
  c.earlier_odometry.pose = truth_from;
  c.earlier_odometry.path_m = 10.0 * static_cast<double>(from);
  c.new_odometry.pose = compose(drift, truth_to);
  c.new_odometry.path_m = path_m;
  return c;
}

TEST(PlaceRecognizer, ClosuresEnterTheGraphOnceAClosureOfAnotherSubmapAgrees) {
  // A second pass 40 m and 25 degrees off in its odometry: closures 3 -> 100 and 4 -> 102 agree
  // (the same drift explains both); 4 -> 101 joins the right submaps turned half round (an alike
  // place) and agrees with neither.
  PlaceRecognitionConfig config;
  config.enabled = true;
  PlaceRecognizer recognizer(config);
  PlaceRecognitionCounts counts;
  const Pose4Dof drift{32.0, -24.0, 0.5, 25.0 * kDegToRad};
  const Pose4Dof e3{30.0, 0.0, 3.5, 0.0}, e4{40.0, 0.5, 3.5, 0.1};
  const Pose4Dof n100{31.0, 0.8, 3.6, 0.05}, n101{36.0, 0.9, 3.6, 0.08}, n102{41.0, 1.0, 3.6, 0.1};
  const VerifiedClosure right_a = closure(3, e3, 100, n100, drift, 1000.0);
  const VerifiedClosure wrong =
      closure(4, e4, 101, n101, drift, 1005.0, Pose4Dof{4.0, -3.0, 0.0, 180.0 * kDegToRad});
  const VerifiedClosure right_b = closure(4, e4, 102, n102, drift, 1010.0);
  EXPECT_LT(closure_disagreement(right_a, right_b, config), 1e-12);
  EXPECT_GT(closure_disagreement(right_a, wrong, config), 1.0);
  EXPECT_GT(closure_disagreement(wrong, right_b, config), 1.0);
  EXPECT_TRUE(recognizer.confirm(100, {right_a}, &counts).empty());
  EXPECT_TRUE(recognizer.confirm(101, {wrong}, &counts).empty());
  const std::vector<SubmapConstraint> confirmed = recognizer.confirm(102, {right_b}, &counts);
  ASSERT_EQ(confirmed.size(), 2u);
  EXPECT_EQ(confirmed[0].to_submap, 100);
  EXPECT_EQ(confirmed[1].to_submap, 102);
  EXPECT_EQ(counts.accepted, 2);
  // Past the window the wrong closure is dropped, counted as unconfirmed.
  EXPECT_TRUE(recognizer.confirm(102 + config.confirm_window_submaps + 1, {}, &counts).empty());
  EXPECT_EQ(counts.unconfirmed, 1);
  EXPECT_EQ(recognizer.waiting(), 0u);
  // Two closures of the same new submap never confirm each other.
  PlaceRecognizer fresh(config);
  PlaceRecognitionCounts same;
  EXPECT_TRUE(
      fresh.confirm(100, {right_a, closure(4, e4, 100, n100, drift, 1000.0)}, &same).empty());
}

TEST(PlaceRecognitionConfig, ValidationNamesTheParameter) {
  PlaceRecognitionConfig config;
  EXPECT_NO_THROW(validate(config));
  config.sectors = 2;
  EXPECT_THROW(validate(config), Error);
  config = PlaceRecognitionConfig();
  config.max_descriptor_distance = 1.5;
  try {
    validate(config);
    ADD_FAILURE() << "accepted a distance above 1";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("place_recognition.max_descriptor_distance"),
              std::string::npos);
  }
}

}  // namespace
}  // namespace pipeline
}  // namespace covox

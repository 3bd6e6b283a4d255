// rostest of ~query_esdf on the demo's flight (test/ros/covoxslam_demo_flight_esdf.test, in the
// rostest node): simulate_flight writes the first scans of the flight `make demo` maps (seed 1,
// 256 columns, motion-distorted scans, the demo's drifting odometry and site), the node maps them
// with the demo's settings (launch/arche.launch, config/arche.yaml), and the distances it
// answers at points near the observed surfaces are compared with the exact distance to the
// simulator's world (its world.ply, world_mesh_reference.h).
//
// Frames: the service answers in mission_frame, the truth is in the simulator's world frame. The
// simulator starts the odometry at the true pose (odom = world at the first scan) and the pose
// graph holds the first submap at its odometry pose (mission = odom there), so the test queries
// the world's points as they are, with no alignment. What separates the frames later is the
// odometry drift that the graph leaves uncorrected; the flight is cut short enough (10 s, the
// first two of the demo's 5 s submaps) that it stays below a voxel: the odometry ends 0.16 m off
// the truth. The test checks this on the node's corrected trajectory (~pose_history against
// truth.tum, within one and a half voxels), so a frame that the test got wrong fails there.
//
// Query points: near surfaces that the LiDAR saw well (from a tenth of the flight's poses), walls
// and obstacles' sides weighted up against the ground. With three views, a ground point at the
// lowest beam's reach, seen at grazing incidence, was once missing from the map when the sensor
// queue had dropped those scans.
//
// Acceptance: at least 95 % of the observed points within one voxel of the exact distance, the
// median error below half a voxel, none off by more than two voxels, at least 1000 points observed
// (300 of them near walls and obstacles' sides). Measured over ten runs on a loaded 2-core machine
// (56 to 90 of the 100 scans integrated, the CPU twin's sensor queue dropping the rest): 97.7 to
// 100 % of about 3240 observed points within one voxel, median error 0.055 to 0.063 m, the largest
// 0.19 to 0.28 m; corrected poses at most 0.15 to 0.18 m off the truth. The runs under 99 % had
// one wall 9 m from the path's end mapped 0.2 m nearer (about 60 points), depending on which
// scans the queue had dropped.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>
#include <covoxslam/EsdfQuery.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>

#include "rostest_scene.h"
#include "world_mesh_reference.h"

// The simulator's build path (cmake/CovoxRosTargets.cmake); empty in a build without the tools.
#ifndef COVOXSLAM_SIMULATE_FLIGHT_PATH
#define COVOXSLAM_SIMULATE_FLIGHT_PATH ""
#endif

namespace {

using namespace covox_rostest;

constexpr double kVoxel_m = 0.2;  // config/covoxslam.yaml's map.voxel_size_m (arche keeps it)
// Query points: offset from a surface point along its normal by this much, and kept where the
// exact distance to the whole world lies in the same band.
constexpr double kNearSurfaceMin_m = 0.2, kNearSurfaceMax_m = 1.0;
// Surfaces sampled: those within this distance of the flown path (well inside the LiDAR's view).
constexpr double kSurfaceNearPath_m = 10.0;
constexpr int kCandidates = 6000;
// A surface whose normal has a smaller vertical part is steep: a wall or an obstacle's side.
constexpr double kSteepNormalZ = 0.7;
constexpr double kSteepSurfaceWeight = 10.0;
// The LiDAR saw a surface point well: from a tenth of the path's poses (at least 3) within
// kViewRange_m (the node's tsdf.max_ray_length_m is 16 m), between the elevations of
// simulate_flight's default OS1-64 (+-16.6 degrees).
constexpr double kViewRange_m = 15.0;
constexpr double kHalfVerticalFov_deg = 16.6;

bool demo_flight_checks() {
  bool value = false;
  ros::NodeHandle("~").getParam("demo_flight", value);
  return value;
}

struct TruthPose {
  double stamp_s;
  Eigen::Vector3d position;
  Eigen::Matrix3d rotation;  // of the cloud frame in the world
};

// A TUM trajectory (stamp x y z qx qy qz qw per line, # comments).
std::vector<TruthPose> read_tum(const std::string& path) {
  std::vector<TruthPose> poses;
  std::ifstream file(path);
  std::string line;
  while (std::getline(file, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    TruthPose pose;
    Eigen::Quaterniond q;
    words >> pose.stamp_s >> pose.position.x() >> pose.position.y() >> pose.position.z() >> q.x() >>
        q.y() >> q.z() >> q.w();
    pose.rotation = q.normalized().toRotationMatrix();
    if (words) poses.push_back(pose);
  }
  return poses;
}

// Runs simulate_flight into `folder`: the demo's flight (tools/run_demo.sh: seed 1, 256
// columns, every other option at its default: distorted scans, the whole flight's drift and
// site), cut after `scans` scans.
int simulate_demo_flight(const fs::path& folder, int scans, std::string* log) {
  const std::string command = std::string(COVOXSLAM_SIMULATE_FLIGHT_PATH) + " --output-dir " +
                              folder.string() + " --seed 1 --columns 256 --max-scans " +
                              std::to_string(scans) + " > " + (folder / "simulate.log").string() +
                              " 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream file((folder / "simulate.log").string());
  log->assign((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  return status;
}

struct QueryPoint {
  Eigen::Vector3d position;
  double truth_m;
  bool near_steep_surface;  // the nearest surface is a wall or an obstacle's side, not ground
};

Eigen::Vector3d nearest_on_path(const std::vector<TruthPose>& path, const Eigen::Vector3d& p) {
  const TruthPose* best = &path.front();
  for (const TruthPose& pose : path)
    if ((pose.position - p).squaredNorm() < (best->position - p).squaredNorm()) best = &pose;
  return best->position;
}

// True when the LiDAR saw the surface point `q` from a tenth of the path's poses: within
// kViewRange_m, inside the beams' elevations (less a degree at either edge), and no triangle in
// between. The ESDF knows only the surfaces the scans hit: the ground right under the drone, for
// one, lies below the lowest beam for the whole flight.
bool surface_point_seen(const WorldMesh& world, const std::vector<TruthPose>& path,
                        const Eigen::Vector3d& q) {
  const double max_sine = std::sin((kHalfVerticalFov_deg - 1.0) * M_PI / 180.0);
  const int needed = std::max(3, static_cast<int>(path.size() / 10));
  int views = 0;
  for (const TruthPose& pose : path) {
    const Eigen::Vector3d ray = pose.position - q;
    const double range = ray.norm();
    if (range > kViewRange_m || range < 0.5) continue;
    const Eigen::Vector3d in_sensor = pose.rotation.transpose() * (-ray);
    if (std::abs(in_sensor.z()) > max_sine * range) continue;
    // Start just off the surface, so that the triangle holding `q` does not count.
    if (!world.line_of_sight(q + ray * (0.02 / range), pose.position)) continue;
    if (++views >= needed) return true;
  }
  return false;
}

// The triangles whose centre lies within kSurfaceNearPath_m of the path, and their weights in the
// sampling: their areas, kSteepSurfaceWeight times that for walls and obstacles' sides (else the
// ground, which covers most of the area, would hold nearly every point).
void triangles_near_path(const WorldMesh& world, const std::vector<TruthPose>& path,
                         std::vector<uint32_t>* near_path, std::vector<double>* weights) {
  for (uint32_t i = 0; i < world.triangles().size(); ++i) {
    const WorldTriangle& t = world.triangles()[i];
    const Eigen::Vector3d centre = (t.a + t.b + t.c) / 3.0;
    if ((nearest_on_path(path, centre) - centre).norm() > kSurfaceNearPath_m) continue;
    near_path->push_back(i);
    const double area = 0.5 * (t.b - t.a).cross(t.c - t.a).norm();
    weights->push_back(std::abs(triangle_normal(t).z()) < kSteepNormalZ ? kSteepSurfaceWeight * area
                                                                        : area);
  }
}

// Points in free space near the observed surfaces around the path: a random point of a triangle
// (by area) moved along its outward normal, kept where the exact distance to the whole world is
// in [kNearSurfaceMin_m, kNearSurfaceMax_m], the path's nearest position sees the point (no
// triangle in between: a point inside a solid, below the ground or behind a wall is left out),
// and the LiDAR saw the point's nearest surface point.
std::vector<QueryPoint> sample_query_points(const WorldMesh& world,
                                            const std::vector<TruthPose>& path, int* unseen) {
  std::vector<uint32_t> near_path;
  std::vector<double> weights;
  triangles_near_path(world, path, &near_path, &weights);
  std::mt19937 random(7);
  std::discrete_distribution<size_t> pick(weights.begin(), weights.end());
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<QueryPoint> points;
  *unseen = 0;
  for (int k = 0; k < kCandidates && !near_path.empty(); ++k) {
    const WorldTriangle& t = world.triangles()[near_path[pick(random)]];
    double u = unit(random), v = unit(random);
    if (u + v > 1.0) u = 1.0 - u, v = 1.0 - v;
    const double offset_m =
        kNearSurfaceMin_m + (kNearSurfaceMax_m - kNearSurfaceMin_m) * unit(random);
    const Eigen::Vector3d p =
        t.a + u * (t.b - t.a) + v * (t.c - t.a) + offset_m * triangle_normal(t);
    Eigen::Vector3d nearest, normal;
    const double truth_m = world.distance(p, kNearSurfaceMax_m, &nearest, &normal);
    if (truth_m < kNearSurfaceMin_m || truth_m > kNearSurfaceMax_m) continue;
    if (!world.line_of_sight(nearest_on_path(path, p), p)) continue;
    if (!surface_point_seen(world, path, nearest)) {
      ++*unseen;
      continue;
    }
    points.push_back({p, truth_m, std::abs(normal.z()) < kSteepNormalZ});
  }
  return points;
}

// The largest distance between a corrected pose of ~pose_history (the cloud frame, in
// mission_frame) and the true pose of the same scan (truth.tum, the cloud frame in the world).
double largest_pose_error_m(const nav_msgs::Path& corrected, const std::vector<TruthPose>& truth,
                            int* matched) {
  double largest = 0.0;
  *matched = 0;
  for (const geometry_msgs::PoseStamped& pose : corrected.poses) {
    const double stamp_s = pose.header.stamp.toSec();
    const auto same = std::find_if(truth.begin(), truth.end(), [&](const TruthPose& t) {
      return std::abs(t.stamp_s - stamp_s) < 1e-4;
    });
    if (same == truth.end()) continue;
    ++*matched;
    const Eigen::Vector3d p(pose.pose.position.x, pose.pose.position.y, pose.pose.position.z);
    largest = std::max(largest, (p - same->position).norm());
  }
  return largest;
}

struct Comparison {
  int observed = 0, within_voxel = 0, beyond_two_voxels = 0;
  int steep_observed = 0, steep_within_voxel = 0;  // those near walls and obstacles' sides
  double median_error_m = 0.0, largest_error_m = 0.0;
};

Comparison compare_with_truth(const std::vector<QueryPoint>& points,
                              const covoxslam::EsdfQuery::Response& response) {
  Comparison result;
  std::vector<double> errors;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!response.observed[i]) continue;
    const double error = std::abs(response.distances_m[i] - points[i].truth_m);
    errors.push_back(error);
    result.within_voxel += error <= kVoxel_m;
    result.steep_observed += points[i].near_steep_surface;
    result.steep_within_voxel += points[i].near_steep_surface && error <= kVoxel_m;
    if (error > 2.0 * kVoxel_m && ++result.beyond_two_voxels <= 10) {
      const Eigen::Vector3d& p = points[i].position;
      std::cout << "demo flight rostest: at (" << p.x() << ", " << p.y() << ", " << p.z()
                << ") the service answers " << response.distances_m[i] << " m, the world "
                << points[i].truth_m << " m\n";
    }
  }
  result.observed = static_cast<int>(errors.size());
  if (errors.empty()) return result;
  result.largest_error_m = *std::max_element(errors.begin(), errors.end());
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  result.median_error_m = errors[errors.size() / 2];
  return result;
}

TEST(CovoxSlamDemoFlight, QueryEsdfMatchesTheSimulatedWorld) {
  if (!demo_flight_checks()) GTEST_SKIP() << "checked in covoxslam_demo_flight_esdf.test";
  if (std::string(COVOXSLAM_SIMULATE_FLIGHT_PATH).empty())
    GTEST_SKIP() << "built without the tools (COVOX_BUILD_TOOLS): no simulate_flight";
  int scans = 100;
  ros::NodeHandle("~").getParam("scans", scans);
  std::mutex path_mutex;
  nav_msgs::Path corrected_path;
  ros::NodeHandle node;
  ros::Subscriber path_subscriber = node.subscribe<nav_msgs::Path>(
      ns("pose_history"), 2, [&](const nav_msgs::Path::ConstPtr& message) {
        std::lock_guard<std::mutex> lock(path_mutex);
        corrected_path = *message;
      });
  ASSERT_TRUE(ros::service::waitForService(ns("query_esdf"), ros::Duration(60.0)))
      << "the nodelet did not come up (see its log above)";

  const fs::path folder =
      fs::temp_directory_path() / ("covoxslam_demo_flight_" + std::to_string(::getpid()));
  fs::create_directories(folder);
  std::string log, message;
  ASSERT_EQ(simulate_demo_flight(folder, scans, &log), 0) << log;
  std::cout << "demo flight rostest: simulate_flight said\n" << log;
  const std::vector<TruthPose> truth = read_tum((folder / "truth.tum").string());
  ASSERT_EQ(truth.size(), static_cast<size_t>(scans));
  const WorldMesh world(read_world_ply((folder / "world.ply").string()), 1.0);
  int unseen = 0;
  const std::vector<QueryPoint> points = sample_query_points(world, truth, &unseen);
  ASSERT_GT(points.size(), 1000u) << "free-space points near the surfaces around the path";

  ASSERT_EQ(play_bag(folder, (folder / "flight.bag").string(), &log), 0) << log;
  ASSERT_TRUE(call_trigger("finish_map", &message)) << message;

  covoxslam::EsdfQuery query;
  for (const QueryPoint& point : points) {
    geometry_msgs::Point p;
    p.x = point.position.x();
    p.y = point.position.y();
    p.z = point.position.z();
    query.request.points.push_back(p);
  }
  ASSERT_TRUE(ros::service::call(ns("query_esdf"), query));
  ASSERT_TRUE(query.response.success) << query.response.message;
  ASSERT_EQ(query.response.distances_m.size(), points.size());
  ASSERT_EQ(query.response.observed.size(), points.size());
  const Comparison result = compare_with_truth(points, query.response);

  // The frames: the corrected poses lie on the true ones (see the comment at the top).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  int matched = 0;
  double pose_error_m = 0.0;
  while (std::chrono::steady_clock::now() < deadline) {
    {
      std::lock_guard<std::mutex> lock(path_mutex);
      pose_error_m = largest_pose_error_m(corrected_path, truth, &matched);
    }
    if (matched > scans / 4) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  std::cout << "demo flight rostest: " << matched << " corrected poses, the farthest "
            << pose_error_m << " m from the truth; " << points.size() << " query points (" << unseen
            << " more left out: their nearest surface was not seen), " << result.observed
            << " observed, " << result.within_voxel
            << " within one voxel (near steep surfaces: " << result.steep_within_voxel << " of "
            << result.steep_observed << "), " << result.beyond_two_voxels
            << " off by more than two; median error " << result.median_error_m << " m, largest "
            << result.largest_error_m << " m\n";
  EXPECT_GT(matched, scans / 4) << "corrected poses matched to the truth";
  EXPECT_LT(pose_error_m, 1.5 * kVoxel_m) << "corrected poses off the truth";

  // Enough points to mean something: most of the sample, spread over the flown surroundings.
  EXPECT_GE(result.observed, std::max<size_t>(1000, points.size() / 2)) << "observed query points";
  EXPECT_GE(result.steep_observed, 300) << "observed points near walls and obstacles' sides";
  EXPECT_GE(result.within_voxel, 0.95 * result.observed)
      << result.within_voxel << " of " << result.observed
      << " observed points within one voxel of the exact distance";
  EXPECT_EQ(result.beyond_two_voxels, 0) << "observed points off by more than two voxels";
  EXPECT_LT(result.median_error_m, 0.5 * kVoxel_m) << "median error";
  fs::remove_all(folder);
}

}  // namespace

// rostest of what a planner uses (test/ros/covoxslam_nodelet_planner.test): the nodelet maps the
// synthetic room's bag; then ~query_esdf's distances are compared with the room's exact distance,
// unobserved and bad points are checked, ~esdf_pointcloud is compared with the room too, the
// submap frames must come on /tf (not /tf_static), and mission -> odom must keep coming while
// finish_map and generate_mesh run (a second bag keeps the simulated clock moving meanwhile).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <iostream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <covoxslam/EsdfQuery.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <tf2_msgs/TFMessage.h>

#include "rostest_scene.h"

namespace {

using namespace covox_rostest;
using Clock = std::chrono::steady_clock;

constexpr double kVoxel_m = 0.2;                  // config/covoxslam.yaml's map.voxel_size_m
constexpr double kPointcloudMaxDistance_m = 0.6;  // ros/esdf_pointcloud_max_distance_m (.test)

bool planner_checks() {
  bool value = false;
  ros::NodeHandle("~").getParam("planner", value);
  return value;
}

// True where `p` is in the room, outside the pillar, and its nearest surface is within
// [min_m, max_m] (close enough that the short flight saw it from nearby).
bool comparable(const Eigen::Vector3d& p, double min_m, double max_m) {
  const bool inside = (p.array() > kRoomMin.array()).all() && (p.array() < kRoomMax.array()).all();
  const bool in_pillar =
      (p.array() > kPillarMin.array()).all() && (p.array() < kPillarMax.array()).all();
  if (!inside || in_pillar) return false;
  const double truth = scene_distance(p);
  return truth >= min_m && truth <= max_m;
}

// What arrives on /tf and /tf_static: arrival times of mission -> odom, and the submap frames.
struct TfRecord {
  std::mutex mutex;
  std::vector<Clock::time_point> correction_arrivals;
  int submap_frames_on_tf = 0;
  int submap_frames_on_tf_static = 0;
};
TfRecord tf_record;

// mission -> odom arrivals within (from, to].
int corrections_between(Clock::time_point from, Clock::time_point to) {
  std::lock_guard<std::mutex> lock(tf_record.mutex);
  int count = 0;
  for (const Clock::time_point& t : tf_record.correction_arrivals) count += t > from && t <= to;
  return count;
}

void expect_queries_match_the_room() {
  // A grid through the room at three heights.
  covoxslam::EsdfQuery query;
  for (double z = 0.7; z < 2.5; z += 0.8) {
    for (double x = -5.8; x < 5.8; x += 0.37) {
      for (double y = -4.8; y < 4.8; y += 0.37) {
        geometry_msgs::Point point;
        point.x = x;
        point.y = y;
        point.z = z;
        query.request.points.push_back(point);
      }
    }
  }
  ASSERT_TRUE(ros::service::call(ns("query_esdf"), query));
  ASSERT_TRUE(query.response.success) << query.response.message;
  const size_t count = query.request.points.size();
  ASSERT_EQ(query.response.distances_m.size(), count);
  ASSERT_EQ(query.response.gradients.size(), count);
  ASSERT_EQ(query.response.observed.size(), count);
  int compared = 0, within_voxel = 0, gradients_compared = 0, gradients_right = 0;
  std::vector<double> errors;
  for (size_t i = 0; i < count; ++i) {
    const geometry_msgs::Point& q = query.request.points[i];
    const Eigen::Vector3d p(q.x, q.y, q.z);
    if (!query.response.observed[i] || !comparable(p, kVoxel_m, 1.2)) continue;
    const double error = std::abs(query.response.distances_m[i] - scene_distance(p));
    errors.push_back(error);
    ++compared;
    if (error <= kVoxel_m) ++within_voxel;
    // The distance grows away from the nearest surface: the gradient points along the exact
    // distance's (a central difference), where that is well defined.
    Eigen::Vector3d truth_gradient;
    for (int axis = 0; axis < 3; ++axis) {
      Eigen::Vector3d step = Eigen::Vector3d::Zero();
      step[axis] = 0.05;
      truth_gradient[axis] = (scene_distance(p + step) - scene_distance(p - step)) / 0.1;
    }
    const geometry_msgs::Vector3& g = query.response.gradients[i];
    const Eigen::Vector3d gradient(g.x, g.y, g.z);
    if (std::abs(truth_gradient.norm() - 1.0) < 0.05 && gradient.norm() > 0.1) {
      ++gradients_compared;
      if (gradient.normalized().dot(truth_gradient) > 0.7) ++gradients_right;
    }
  }
  ASSERT_GT(compared, 100) << "observed points near the room's surfaces: " << compared;
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  EXPECT_LT(errors[errors.size() / 2], 0.5 * kVoxel_m) << "median error";
  EXPECT_GE(within_voxel, 0.9 * compared)
      << within_voxel << " of " << compared << " within one voxel of the exact distance";
  EXPECT_GE(gradients_right, 0.85 * gradients_compared)
      << gradients_right << " of " << gradients_compared << " gradients along the exact one";
  std::cout << "planner rostest: query_esdf " << within_voxel << " of " << compared
            << " observed points within one voxel, median error " << errors[errors.size() / 2]
            << " m; " << gradients_right << " of " << gradients_compared << " gradients right\n";
}

void expect_unobserved_and_bad_points_answered() {
  covoxslam::EsdfQuery query;
  geometry_msgs::Point outside;  // far beyond the room: never observed
  outside.x = 40.0;
  query.request.points.push_back(outside);
  ASSERT_TRUE(ros::service::call(ns("query_esdf"), query));
  ASSERT_TRUE(query.response.success) << query.response.message;
  ASSERT_EQ(query.response.observed.size(), 1u);
  EXPECT_FALSE(query.response.observed[0]);

  covoxslam::EsdfQuery bad;
  bad.request.points.resize(3);
  bad.request.points[1].y = std::nan("");
  ASSERT_TRUE(ros::service::call(ns("query_esdf"), bad));
  EXPECT_FALSE(bad.response.success);
  EXPECT_NE(bad.response.message.find("point 1"), std::string::npos) << bad.response.message;
}

void expect_pointcloud_matches_the_room(const sensor_msgs::PointCloud2& cloud) {
  ASSERT_EQ(cloud.header.frame_id, "mission");
  ASSERT_EQ(cloud.fields.size(), 4u);
  EXPECT_EQ(cloud.fields[0].name, "x");
  EXPECT_EQ(cloud.fields[3].name, "intensity");
  ASSERT_EQ(cloud.point_step, 16u);
  ASSERT_GT(cloud.width, 1000u);
  int compared = 0, within_voxel = 0;
  for (uint32_t i = 0; i < cloud.width; ++i) {
    float v[4];
    std::memcpy(v, cloud.data.data() + 16 * i, sizeof(v));
    EXPECT_LE(v[3], kPointcloudMaxDistance_m + 1e-4);
    const Eigen::Vector3d p(v[0], v[1], v[2]);
    // Up to a voxel less than the band: a voxel truly farther is listed only when underestimated.
    if (!comparable(p, kVoxel_m, kPointcloudMaxDistance_m - kVoxel_m)) continue;
    ++compared;
    if (std::abs(v[3] - scene_distance(p)) <= kVoxel_m) ++within_voxel;
  }
  ASSERT_GT(compared, 300);
  EXPECT_GE(within_voxel, 0.9 * compared) << within_voxel << " of " << compared;
  std::cout << "planner rostest: esdf_pointcloud " << cloud.width << " points, " << within_voxel
            << " of " << compared << " comparable ones within one voxel\n";
}

// The flight goes on (the clock moves, so mission -> odom is published) while finish_map and
// generate_mesh (which re-sends every mesh) run one after the other, on the services' thread;
// none may hold the correction back.
void expect_tf_flows_during_service_calls(const fs::path& folder) {
  std::string message;
  const std::string second = (folder / "second.bag").string();
  write_bag(second, kStart_s + kClouds * kCloudPeriod_s + 1.0, 3 * kClouds, false);
  std::atomic<bool> playing{true};
  std::thread player([&] {
    std::string play_log;
    play_bag(folder, second, &play_log);
    playing = false;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(3500));  // past rosbag's 2 s delay
  // A call's first 30 ms are left out: what was sent just before it may still be arriving.
  const auto settle = std::chrono::milliseconds(30);
  double call_time_s = 0.0, longest_call_s = 0.0;
  std::vector<std::pair<Clock::time_point, Clock::time_point>> windows;
  int calls = 0;
  while (playing && calls < 6) {
    const auto start = Clock::now();
    const bool ok = call_trigger(calls % 2 == 0 ? "finish_map" : "generate_mesh", &message);
    const auto end = Clock::now();
    EXPECT_TRUE(ok) << message;
    ++calls;
    if (!playing) break;  // the clock stopped during the call: no correction to expect
    const double duration_s = std::chrono::duration<double>(end - start).count();
    longest_call_s = std::max(longest_call_s, duration_s);
    if (duration_s <= 0.03) continue;
    call_time_s += duration_s - 0.03;
    windows.emplace_back(start + settle, end);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  player.join();
  int during_calls = 0;
  for (const auto& window : windows)
    during_calls += corrections_between(window.first, window.second);
  // tf_publish_period_s is 0.05 s. A thread shared with the services sends nothing while a call
  // runs; its own thread keeps the rate (a loaded machine may delay some sends).
  const double expected = call_time_s / 0.05;
  EXPECT_GE(calls, 2);
  EXPECT_GE(expected, 3.0) << "the calls were too short to tell (" << call_time_s << " s)";
  EXPECT_GE(during_calls, 0.5 * expected) << during_calls << " mission -> odom transforms during "
                                          << call_time_s << " s of service calls";
  std::cout << "planner rostest: " << calls << " service calls (" << call_time_s
            << " s, the longest " << longest_call_s << " s): " << during_calls
            << " mission -> odom transforms meanwhile, " << expected << " at the full rate\n";
}

TEST(CovoxSlamPlanner, EsdfForPlannersAndTfWhileServicesRun) {
  if (!planner_checks()) GTEST_SKIP() << "checked in covoxslam_nodelet_planner.test";
  ros::NodeHandle node;
  std::mutex cloud_mutex;
  sensor_msgs::PointCloud2 esdf_cloud;
  ros::Subscriber cloud_subscriber = node.subscribe<sensor_msgs::PointCloud2>(
      ns("esdf_pointcloud"), 2, [&](const sensor_msgs::PointCloud2::ConstPtr& m) {
        std::lock_guard<std::mutex> lock(cloud_mutex);
        esdf_cloud = *m;
      });
  auto on_tf = [](const tf2_msgs::TFMessage::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(tf_record.mutex);
    for (const auto& t : m->transforms) {
      if (t.header.frame_id == "mission" && t.child_frame_id == "odom")
        tf_record.correction_arrivals.push_back(Clock::now());
      if (t.child_frame_id.rfind("submap_", 0) == 0) ++tf_record.submap_frames_on_tf;
    }
  };
  auto on_tf_static = [](const tf2_msgs::TFMessage::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(tf_record.mutex);
    for (const auto& t : m->transforms)
      if (t.child_frame_id.rfind("submap_", 0) == 0) ++tf_record.submap_frames_on_tf_static;
  };
  ros::Subscriber tf_subscriber = node.subscribe<tf2_msgs::TFMessage>("/tf", 100, +on_tf);
  ros::Subscriber tf_static_subscriber =
      node.subscribe<tf2_msgs::TFMessage>("/tf_static", 10, +on_tf_static);
  ASSERT_TRUE(ros::service::waitForService(ns("query_esdf"), ros::Duration(60.0)))
      << "the nodelet did not come up (see its log above)";

  const fs::path folder =
      fs::temp_directory_path() / ("covoxslam_planner_" + std::to_string(::getpid()));
  fs::create_directories(folder);
  const std::string first = (folder / "first.bag").string();
  write_bag(first);
  std::string log, message;
  ASSERT_EQ(play_bag(folder, first, &log), 0) << log;
  ASSERT_TRUE(call_trigger("finish_map", &message)) << message;

  expect_queries_match_the_room();
  expect_unobserved_and_bad_points_answered();
  // finish_map published the cloud (latched).
  const auto cloud_deadline = Clock::now() + std::chrono::seconds(10);
  auto has_cloud = [&] {
    std::lock_guard<std::mutex> lock(cloud_mutex);
    return esdf_cloud.width > 0;
  };
  while (!has_cloud() && Clock::now() < cloud_deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  {
    std::lock_guard<std::mutex> lock(cloud_mutex);
    expect_pointcloud_matches_the_room(esdf_cloud);
  }

  expect_tf_flows_during_service_calls(folder);
  {
    std::lock_guard<std::mutex> lock(tf_record.mutex);
    EXPECT_GT(tf_record.submap_frames_on_tf, 0);
    EXPECT_EQ(tf_record.submap_frames_on_tf_static, 0);
  }
  fs::remove_all(folder);
}

}  // namespace

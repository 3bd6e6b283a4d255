// SlamNode's outputs for planners: ~query_esdf (distance, gradient and observed flag at a batch of
// mission-frame points, on its own thread) and ~esdf_pointcloud (the 3-D ESDF near surfaces,
// published by the visualisation thread). Both read SlamSystem's ESDF of the finished submaps at
// their corrected poses; where submaps overlap the smaller distance wins, as in ~esdf_slice.
#include <cmath>
#include <string>
#include <vector>

#include "covoxslam/ros/message_conversions.h"
#include "covoxslam/ros/slam_node.h"

namespace covox {
namespace ros_layer {

void SlamNode::publish_esdf_pointcloud_locked(bool force, const ros::Time& stamp) {
  if (!options_.publish_esdf_pointcloud) return;
  if (!force && !esdf_pointcloud_stale_) return;
  // Costs a pass over every finished submap: only for a listener, or when a map operation asks
  // for it (the cloud is latched for whoever comes later).
  if (!force && esdf_pointcloud_publisher_.getNumSubscribers() == 0) return;
  bool truncated = false;
  const std::vector<integrators::SlicePoint> voxels = slam_->esdf_voxels_world(
      options_.esdf_pointcloud_max_distance_m,
      static_cast<size_t>(options_.esdf_pointcloud_max_points), &truncated);
  if (truncated) {
    ROS_WARN_STREAM_THROTTLE(30.0, "covoxslam: ~esdf_pointcloud holds the "
                                       << options_.esdf_pointcloud_max_points
                                       << " voxels nearest to surfaces only (more lie within "
                                       << options_.esdf_pointcloud_max_distance_m
                                       << " m; raise ros/esdf_pointcloud_max_points)");
  }
  esdf_pointcloud_publisher_.publish(slice_cloud(voxels, options_.mission_frame, stamp));
  esdf_pointcloud_stale_ = false;
}

bool SlamNode::query_esdf(covoxslam::EsdfQuery::Request& request,
                          covoxslam::EsdfQuery::Response& response) {
  response.success = false;
  const size_t count = request.points.size();
  if (count > static_cast<size_t>(options_.esdf_query_max_points)) {
    response.message = "refused: " + std::to_string(count) + " points, more than ros/" +
                       "esdf_query_max_points (" + std::to_string(options_.esdf_query_max_points) +
                       "); split the request";
    return true;
  }
  std::vector<Vec3f> points(count);
  for (size_t i = 0; i < count; ++i) {
    const geometry_msgs::Point& p = request.points[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      response.message = "refused: point " + std::to_string(i) + " is not finite";
      return true;
    }
    points[i] = Vec3f(static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z));
  }
  std::vector<integrators::EsdfSample> samples;
  try {
    samples = slam_->query_esdf_world(points);
  } catch (const std::exception& error) {
    response.message = std::string("the ESDF query failed: ") + error.what();
    ROS_ERROR_STREAM("covoxslam: query_esdf: " << response.message);
    return true;
  }
  response.distances_m.resize(count, 0.0f);
  response.gradients.resize(count);
  response.observed.resize(count, 0);
  size_t observed = 0;
  for (size_t i = 0; i < count; ++i) {
    if (!samples[i].valid) continue;
    response.distances_m[i] = samples[i].distance_m;
    response.gradients[i].x = samples[i].gradient.x;
    response.gradients[i].y = samples[i].gradient.y;
    response.gradients[i].z = samples[i].gradient.z;
    response.observed[i] = 1;
    ++observed;
  }
  response.success = true;
  response.message = std::to_string(observed) + " of " + std::to_string(count) +
                     " points observed, in " + options_.mission_frame;
  return true;
}

}  // namespace ros_layer
}  // namespace covox

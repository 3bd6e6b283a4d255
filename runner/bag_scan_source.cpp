#include "runner/bag_scan_source.h"

#include <optional>
#include <sstream>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/io/transform_numbers.h"
#include "covoxslam/io/rosbag_messages.h"

namespace covox {
namespace tools {

namespace rb = io::rosbag;

namespace {

// tf2_msgs/TFMessage and the older tf/tfMessage have the same layout and MD5 sum.
bool is_tf_type(const std::string& type) {
  return type == "tf2_msgs/TFMessage" || type == "tf/tfMessage";
}

std::string topic_list(const rb::BagReader& bag) {
  std::ostringstream list;
  for (const rb::BagConnection& connection : bag.connections()) {
    list << "\n  " << connection.topic << " (" << connection.type << ")";
  }
  return list.str();
}

// The type of `topic` in the bag; empty when the bag has no such topic.
std::string topic_type(const rb::BagReader& bag, const std::string& topic) {
  for (const rb::BagConnection& connection : bag.connections()) {
    if (connection.topic == topic) return connection.type;
  }
  return std::string();
}

// The poses of one trajectory topic, added message by message, so that read_bag_trajectory and
// the scan source's single pass over the bag read them alike.
class TrajectoryTopic {
 public:
  // Throws covox::Error for a missing topic or another type, listing the bag's topics.
  TrajectoryTopic(const rb::BagReader& bag, const std::string& topic)
      : what_("bag '" + bag.path() + "' " + topic) {
    const std::string type = topic_type(bag, topic);
    positions_only_ = type == rb::point_stamped_type().name;
    if (!positions_only_ && type != rb::odometry_type().name) {
      throw Error("bag '" + bag.path() + "': trajectory topic '" + topic + "' is " +
                  (type.empty() ? std::string("missing") : "a " + type) +
                  "; geometry_msgs/PointStamped or nav_msgs/Odometry expected. Its topics:" +
                  topic_list(bag));
    }
    trajectory_.has_orientations = !positions_only_;
  }

  void add(const rb::BagMessage& message) {
    io::StampedPose pose;
    if (positions_only_) {
      const rb::PointStampedMessage fix =
          rb::parse_point_stamped(message.data.data(), message.data.size(), what_);
      pose.timestamp_s = fix.header.stamp.to_seconds();
      pose.position_m = fix.point;
    } else {
      const rb::OdometryMessage odometry =
          rb::parse_odometry(message.data.data(), message.data.size(), what_);
      pose.timestamp_s = odometry.header.stamp.to_seconds();
      pose.position_m = odometry.T_parent_child.translation();
      pose.orientation = Eigen::Quaterniond(odometry.T_parent_child.linear());
    }
    // Evaluation needs strictly increasing stamps: a repeated or out-of-order pose is left out.
    if (!trajectory_.poses.empty() && pose.timestamp_s <= trajectory_.poses.back().timestamp_s)
      return;
    if (!pose.position_m.allFinite()) return;
    trajectory_.poses.push_back(pose);
  }

  io::Trajectory& trajectory() { return trajectory_; }

 private:
  std::string what_;
  bool positions_only_ = false;
  io::Trajectory trajectory_;
};

}  // namespace

io::Trajectory read_bag_trajectory(rb::BagReader& bag, const std::string& topic) {
  TrajectoryTopic poses(bag, topic);
  for (const rb::IndexEntry& entry : bag.index({topic})) poses.add(bag.read(entry));
  return std::move(poses.trajectory());
}

BagScanSource::BagScanSource(const std::string& path, const BagScanOptions& options)
    : path_(path), options_(options), bag_(path) {
  const std::string cloud_type = topic_type(bag_, options_.cloud_topic);
  if (cloud_type.empty()) {
    throw Error("bag '" + path + "' has no topic '" + options_.cloud_topic +
                "' (--cloud-topic); its topics:" + topic_list(bag_));
  }
  if (cloud_type != rb::point_cloud2_type().name) {
    throw Error("bag '" + path + "': topic '" + options_.cloud_topic + "' is a " + cloud_type +
                ", not a sensor_msgs/PointCloud2");
  }
  if (!options_.odometry_topic.empty()) {
    const std::string type = topic_type(bag_, options_.odometry_topic);
    if (type != rb::odometry_type().name) {
      throw Error("bag '" + path + "': odometry topic '" + options_.odometry_topic + "' is " +
                  (type.empty() ? std::string("missing") : "a " + type) +
                  ", expected nav_msgs/Odometry; its topics:" + topic_list(bag_));
    }
  }
  read_poses();
  clouds_ = bag_.index({options_.cloud_topic});
}

void BagScanSource::read_poses() {
  std::vector<std::string> topics = {"/tf", "/tf_static"};
  if (!options_.odometry_topic.empty()) topics.push_back(options_.odometry_topic);
  std::optional<TrajectoryTopic> reference;
  if (!options_.reference_topic.empty() && !topic_type(bag_, options_.reference_topic).empty()) {
    reference.emplace(bag_, options_.reference_topic);
    topics.push_back(options_.reference_topic);
  }
  // One pass in time order for all of them: a compressed bag's chunks are decompressed once here
  // (they hold these messages between the clouds), not once per topic.
  for (const rb::IndexEntry& entry : bag_.index(topics)) {
    const rb::BagMessage message = bag_.read(entry);
    const std::string& topic = message.connection->topic;
    const std::string what = "bag '" + path_ + "' " + topic;
    if ((topic == "/tf" || topic == "/tf_static") && is_tf_type(message.connection->type)) {
      const rb::TfMessage tf = rb::parse_tf_message(message.data.data(), message.data.size(), what);
      for (const rb::TransformStamped& transform : tf.transforms)
        tf_.add(transform, topic == "/tf_static");
    }
    if (topic == options_.odometry_topic) {
      const rb::OdometryMessage odometry =
          rb::parse_odometry(message.data.data(), message.data.size(), what);
      tf_.add(odometry.header.frame_id, odometry.child_frame_id, odometry.header.stamp.to_seconds(),
              odometry.T_parent_child, /*is_static=*/false);
    }
    if (reference && topic == options_.reference_topic) reference->add(message);
  }
  if (reference) {
    reference_ = std::move(reference->trajectory());
    if (!reference_.poses.empty()) reference_kind_ = ReferenceKind::kGroundTruth;
  }
}

bool BagScanSource::next(SourceScan* scan) {
  while (next_cloud_ < clouds_.size()) {
    const rb::IndexEntry entry = clouds_[next_cloud_++];
    const std::string what = "bag '" + path_ + "' " + options_.cloud_topic + " at " +
                             std::to_string(entry.time.to_seconds()) + " s";
    try {
      const rb::BagMessage message = bag_.read(entry);
      const rb::PointCloud2Message cloud =
          rb::parse_point_cloud2(message.data.data(), message.data.size(), what);
      const std::string frame =
          options_.sensor_frame.empty() ? cloud.header.frame_id : options_.sensor_frame;
      const double stamp_s = cloud.header.stamp.to_seconds();
      std::string reason;
      Eigen::Isometry3d T_odom_sensor;
      if (!lookup_sensor_pose(frame, stamp_s, &T_odom_sensor, &reason)) {
        log_dropped_scan(++dropped_, what + ": " + reason);
        continue;
      }
      io::ReadStats stats;
      const io::PointCloud points =
          rb::extract_points(cloud, what, &stats, options_.column_sweep_duration_s);
      dropped_non_finite_points_ += static_cast<int64_t>(stats.dropped_non_finite_points);
      scan->stamp_s = stamp_s;
      scan->T_odom_sensor = T_odom_sensor;
      scan->colors.clear();
      keep_points(points, scan);
      scan->sweep = sweep_odometry(stamp_s, scan->point_times_s,
                                   [&](double at_s, Eigen::Isometry3d* T_odom_sensor) {
                                     return lookup_sensor_pose(frame, at_s, T_odom_sensor, nullptr);
                                   });
      return true;
    } catch (const Error& error) {
      log_dropped_scan(++dropped_, error.what());
    }
  }
  return false;
}

void BagScanSource::keep_points(const io::PointCloud& points, SourceScan* scan) const {
  scan->points_sensor_m.clear();
  scan->points_sensor_m.reserve(points.size());
  scan->point_times_s.clear();
  const bool timed = !points.times_s.empty();
  const float min_range_squared = static_cast<float>(options_.min_range_m * options_.min_range_m);
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3f& p = points.points_m[i];
    if (p.squaredNorm() < min_range_squared) continue;
    scan->points_sensor_m.emplace_back(p.x(), p.y(), p.z());
    if (timed) scan->point_times_s.push_back(points.times_s[i]);
  }
}

bool BagScanSource::lookup_sensor_pose(const std::string& frame, double stamp_s,
                                       Eigen::Isometry3d* T_odom_sensor, std::string* reason) {
  if (!options_.T_base_sensor)
    return tf_.lookup(options_.odom_frame, frame, stamp_s, T_odom_sensor, reason);
  Eigen::Isometry3d T_odom_base;
  if (!tf_.lookup(options_.odom_frame, options_.base_frame, stamp_s, &T_odom_base, reason))
    return false;
  *T_odom_sensor = T_odom_base * *options_.T_base_sensor;
  if (!extrinsic_logged_) {
    extrinsic_logged_ = true;
    const std::string given = options_.base_frame + " -> " + frame + " from " +
                              options_.extrinsic_origin + ": " +
                              io::transform_to_text(*options_.T_base_sensor);
    Eigen::Isometry3d T_bag;
    if (tf_.lookup(options_.base_frame, frame, stamp_s, &T_bag)) {
      log_info("bag '", path_, "': its tf also has ", options_.base_frame, " -> ", frame, " (",
               io::transform_to_text(T_bag), "); the given extrinsic wins: ", given);
    } else {
      log_info("bag '", path_, "': extrinsic ", given);
    }
  }
  return true;
}

std::string BagScanSource::describe() const {
  std::ostringstream text;
  text << "bag " << path_ << ", " << clouds_.size() << " clouds on " << options_.cloud_topic
       << ", odometry "
       << (options_.odometry_topic.empty() ? "tf from '" + options_.odom_frame + "'"
                                           : "topic " + options_.odometry_topic)
       << ", " << tf_.dynamic_sample_count() << " dynamic tf samples";
  if (options_.T_base_sensor) {
    text << ", extrinsic " << options_.base_frame << " -> sensor from " << options_.extrinsic_origin
         << " (" << io::transform_to_text(*options_.T_base_sensor) << ")";
  }
  if (reference_kind_ != ReferenceKind::kNone) {
    text << ", reference " << options_.reference_topic << " (" << reference_.size() << " poses)";
  }
  if (dropped_non_finite_points_ > 0)
    text << ", " << dropped_non_finite_points_ << " non-finite points dropped so far";
  return text.str();
}

double BagScanSource::duration_s() const {
  if (clouds_.size() < 2) return 0.0;
  const double span_s = clouds_.back().time.to_seconds() - clouds_.front().time.to_seconds();
  return span_s * clouds_.size() / (clouds_.size() - 1);  // plus one scan period
}

}  // namespace tools
}  // namespace covox

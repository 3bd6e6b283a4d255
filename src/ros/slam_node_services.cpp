// SlamNode services: save / load the map, save the trajectory (TUM) and the mesh (PLY), publish
// the meshes now, finish the map, optimise, reset. After finish_map, reset and load_map the node
// maps the next clouds. They run on the output thread; every failure
// is answered with success = false and a message saying why (never an exception into roscpp).
// The file services read and write only inside ~ros/output_dir (io/output_folder.h): a request's
// file_path is a plain relative name, and an existing file is replaced only with overwrite.
#include <exception>
#include <functional>
#include <utility>

#include "covoxslam/core/error.h"
#include "covoxslam/io/atomic_file.h"
#include "covoxslam/io/map_file.h"
#include "covoxslam/io/submap_codec.h"
#include "covoxslam/io/mesh_ply.h"
#include "covoxslam/io/trajectory_io.h"
#include "covoxslam/ros/slam_node.h"

namespace covox {
namespace ros_layer {

namespace {

// Runs `action`, turning an exception into a failed response; logs the outcome.
template <class Response>
bool answer(const char* service, Response& response, const std::function<std::string()>& action) {
  try {
    response.message = action();
    response.success = true;
    ROS_INFO_STREAM("covoxslam: " << service << ": " << response.message);
  } catch (const std::exception& error) {
    response.success = false;
    response.message = error.what();
    ROS_ERROR_STREAM("covoxslam: " << service << " failed: " << response.message);
  }
  return true;
}

// Runs `on_exit` when the scope ends, also by an exception.
class ScopeExit {
 public:
  explicit ScopeExit(std::function<void()> on_exit) : on_exit_(std::move(on_exit)) {}
  ~ScopeExit() { on_exit_(); }
  ScopeExit(const ScopeExit&) = delete;
  ScopeExit& operator=(const ScopeExit&) = delete;

 private:
  std::function<void()> on_exit_;
};

}  // namespace

bool SlamNode::save_map(covoxslam::FilePath::Request& request,
                        covoxslam::FilePath::Response& response) {
  return answer("save_map", response, [&] {
    const std::string path = output_folder_.display(request.file_path);
    io::MapFileWriter writer(output_folder_.target(request.file_path, request.overwrite),
                             slam_->config().map.voxel_size_m, slam_->config().map.voxels_per_side,
                             slam_->map_distance_scale_m());
    uint64_t blocks = 0;
    slam_->write_submaps([&](int64_t id, const Eigen::Isometry3d& T_world_submap,
                             const std::vector<uint8_t>& encoded) {
      writer.add_submap(id, T_world_submap, encoded);
      blocks += io::validate_encoded_submap(encoded.data(), encoded.size(), "save_map").blocks;
    });
    writer.commit();
    return "saved " + std::to_string(writer.submaps_written()) + " submaps (" +
           std::to_string(blocks) + " blocks) to " + path;
  });
}

bool SlamNode::load_map(covoxslam::FilePath::Request& request,
                        covoxslam::FilePath::Response& response) {
  return answer("load_map", response, [&] {
    const std::string path = output_folder_.display(request.file_path);
    // Compact forms: a map larger than the memory budget is never decoded whole.
    io::MapFileContents contents = io::load_map_file(
        output_folder_.open_for_reading(request.file_path), path, io::MapFileVoxels::kEncoded);
    if (contents.voxel_size_m != slam_->config().map.voxel_size_m ||
        contents.voxels_per_side != slam_->config().map.voxels_per_side) {
      throw Error("the map in " + path + " has voxel size " +
                  std::to_string(contents.voxel_size_m) + " m and " +
                  std::to_string(contents.voxels_per_side) +
                  " voxels per side, the running system " +
                  std::to_string(slam_->config().map.voxel_size_m) + " m and " +
                  std::to_string(slam_->config().map.voxels_per_side) +
                  " (set voxel_size_m / voxels_per_side)");
    }
    std::vector<pipeline::SubmapSnapshot> submaps;
    for (io::SubmapRecord& record : contents.submaps) {
      submaps.push_back(pipeline::SubmapSnapshot{
          record.id, record.T_world_submap, {}, std::move(record.encoded)});
    }
    const size_t count = submaps.size();
    {
      // Scans waiting for tf belong to the replaced map.
      std::lock_guard<std::mutex> lock(input_mutex_);
      pending_.clear();
    }
    slam_->load_submaps(std::move(submaps));
    {
      // The loaded map starts a new time line: earlier stamps (a bag played again) are mapped.
      std::lock_guard<std::mutex> lock(input_mutex_);
      clear_input_locked();
    }
    slam_->resume();
    clear_published_markers();
    publish_map(false, true);
    return "loaded " + std::to_string(count) + " submaps from " + path +
           "; mapping continues in a new submap with the next cloud";
  });
}

bool SlamNode::save_trajectory(covoxslam::FilePath::Request& request,
                               covoxslam::FilePath::Response& response) {
  return answer("save_trajectory", response, [&] {
    const io::WriteTarget target = output_folder_.target(request.file_path, request.overwrite);
    io::Trajectory trajectory;
    for (const pipeline::StampedPose& pose : slam_->corrected_trajectory()) {
      io::StampedPose stamped;
      stamped.timestamp_s = pose.stamp_s;
      stamped.position_m = pose.T_world_sensor.translation();
      stamped.orientation = Eigen::Quaterniond(pose.T_world_sensor.linear()).normalized();
      trajectory.poses.push_back(stamped);
    }
    io::write_file(target, "save_trajectory",
                   [&](std::ostream& file) { io::write_tum_trajectory(file, trajectory); });
    return "saved " + std::to_string(trajectory.size()) + " corrected poses (TUM) to " +
           target.display;
  });
}

bool SlamNode::save_mesh(covoxslam::FilePath::Request& request,
                         covoxslam::FilePath::Response& response) {
  return answer("save_mesh", response, [&] {
    const io::WriteTarget target = output_folder_.target(request.file_path, request.overwrite);
    const map::Mesh mesh = slam_->combined_mesh();
    io::write_file(target, "save_mesh",
                   [&](std::ostream& file) { io::write_mesh_ply(file, mesh); });
    return "saved " + std::to_string(mesh.triangle_count()) + " triangles (PLY) to " +
           target.display;
  });
}

bool SlamNode::generate_mesh(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  return answer("generate_mesh", response, [&] {
    publish_map(true, true);
    return "published the meshes of " + std::to_string(slam_->submaps().size()) + " submaps (" +
           std::to_string(slam_->combined_mesh().triangle_count()) + " triangles)";
  });
}

bool SlamNode::finish_map(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  return answer("finish_map", response, [&] {
    {
      // What waits for tf now gets one last chance; clouds arriving from now on wait until the
      // SLAM system runs again.
      std::lock_guard<std::mutex> lock(input_mutex_);
      process_pending_locked();
      finishing_ = true;
    }
    bool resumed = false;
    {
      const ScopeExit map_on([&] {
        resumed = slam_->resume();
        std::lock_guard<std::mutex> lock(input_mutex_);
        finishing_ = false;
        process_pending_locked();
      });
      // Every queued cloud is integrated, the active submap finished, the graph optimised.
      slam_->finish();
      publish_map(false, true);
    }
    if (!resumed) throw Error("the SLAM system was shut down: mapping cannot continue");
    const pipeline::SlamCounters counters = slam_->counters();
    return "finished: " + std::to_string(counters.scans_integrated) + " scans in " +
           std::to_string(slam_->submaps().size()) + " submaps, " +
           std::to_string(counters.optimizations) +
           " optimisations; mapping continues in a new submap with the next cloud";
  });
}

bool SlamNode::optimize_pose_graph(std_srvs::Trigger::Request&,
                                   std_srvs::Trigger::Response& response) {
  return answer("optimize_pose_graph", response, [&] {
    slam_->request_optimization();
    return std::string("optimisation requested");
  });
}

bool SlamNode::reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  return answer("reset", response, [&] {
    {
      // Also forgets the time line: the next cloud may be older than the last one (a bag
      // played again), and a refusal after a time jump ends here.
      std::lock_guard<std::mutex> lock(input_mutex_);
      clear_input_locked();
    }
    slam_->reset();
    slam_->resume();
    clear_published_markers();
    publish_map(false, true);
    return std::string("the map is empty; mapping continues with the next cloud");
  });
}

}  // namespace ros_layer
}  // namespace covox

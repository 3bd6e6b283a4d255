// SlamSystem: what comes from outside besides scans - loop closures, GNSS positions and heights,
// optimisation requests, reset() and load_submaps().
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/io/submap_codec.h"
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace pipeline {

namespace {

// The first refusal of a kind and then every 100th are logged; the counters hold the exact count.
bool should_log_refusal(int64_t count_after) { return count_after == 1 || count_after % 100 == 0; }

}  // namespace

const SlamSystem::TrajectoryEntry* SlamSystem::scan_near_locked(double stamp_s) const {
  if (!std::isfinite(stamp_s) || trajectory_.empty()) return nullptr;
  // Stamps increase along trajectory_ (add_scan refuses others; reset() clears it).
  auto after = std::lower_bound(
      trajectory_.begin(), trajectory_.end(), stamp_s,
      [](const TrajectoryEntry& entry, double value) { return entry.stamp_s < value; });
  const TrajectoryEntry* best = nullptr;
  double best_gap = config_.external_stamp_tolerance_s;
  if (after != trajectory_.end() && std::abs(after->stamp_s - stamp_s) <= best_gap) {
    best = &*after;
    best_gap = std::abs(after->stamp_s - stamp_s);
  }
  if (after != trajectory_.begin() && std::abs((after - 1)->stamp_s - stamp_s) <= best_gap)
    best = &*(after - 1);
  return best;
}

ExternalConstraintCounters& SlamSystem::external_counters_locked(SubmapConstraintKind kind) {
  switch (kind) {
    case SubmapConstraintKind::kAbsolutePosition:
      return counters_.absolute_positions;
    case SubmapConstraintKind::kHeight:
      return counters_.heights;
    default:
      return counters_.loop_closures;
  }
}

void SlamSystem::refuse_locked(int64_t* counter, const char* what, const std::string& why) {
  const int64_t count_after = ++*counter;
  if (should_log_refusal(count_after)) {
    log_warning("SLAM: refused ", what, ": ", why, " (", count_after, " such refusals so far)");
  }
}

bool SlamSystem::add_loop_closure(const LoopClosure& closure) {
  const std::string problem = loop_closure_problem(closure);
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    ExternalConstraintCounters& counts = counters_.loop_closures;
    ++counts.received;
    if (!problem.empty()) {
      refuse_locked(&counts.rejected_bad_input, "a loop closure", problem);
      return false;
    }
    const TrajectoryEntry* from = scan_near_locked(closure.from_stamp_s);
    const TrajectoryEntry* to = scan_near_locked(closure.to_stamp_s);
    if (!from || !to) {
      refuse_locked(&counts.rejected_unknown_stamp, "a loop closure",
                    "no integrated scan within " +
                        std::to_string(config_.external_stamp_tolerance_s) + " s of " +
                        (from ? "to_stamp " + std::to_string(closure.to_stamp_s)
                              : "from_stamp " + std::to_string(closure.from_stamp_s)));
      return false;
    }
    if (from->submap_id == to->submap_id) {
      refuse_locked(&counts.rejected_same_submap, "a loop closure",
                    "both stamps lie in submap " + std::to_string(from->submap_id) +
                        " (a submap is rigid: there is nothing to correct)");
      return false;
    }
    const RelativeConstraint4Dof projected =
        project_loop_closure(from->T_odom_submap.inverse() * from->T_odom_sensor, closure.T_from_to,
                             to->T_odom_submap.inverse() * to->T_odom_sensor, closure.information);
    const std::string projected_problem = information_problem(projected.information);
    if (!projected_problem.empty() || !projected.information.allFinite()) {
      refuse_locked(
          &counts.rejected_bad_input, "a loop closure",
          "its information says nothing about x, y, z or yaw (" + projected_problem + ")");
      return false;
    }
    SubmapConstraint constraint;
    constraint.kind = SubmapConstraintKind::kLoopClosure;
    constraint.from_submap = from->submap_id;
    constraint.to_submap = to->submap_id;
    constraint.measurement = projected.measurement;
    constraint.information = projected.information;
    pending_constraints_.push_back(constraint);
  }
  submap_queue_.wake();
  return true;
}

bool SlamSystem::add_absolute_position(double stamp_s, const Eigen::Vector3d& position_world_m,
                                       const Eigen::Matrix3d& information) {
  std::string problem;
  if (!std::isfinite(stamp_s)) {
    problem = "the stamp is not finite";
  } else if (!position_world_m.allFinite()) {
    problem = "the position is not finite";
  } else {
    problem = information_problem(information);
  }
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    ExternalConstraintCounters& counts = counters_.absolute_positions;
    ++counts.received;
    if (!problem.empty()) {
      refuse_locked(&counts.rejected_bad_input, "an absolute position", problem);
      return false;
    }
    const TrajectoryEntry* scan = scan_near_locked(stamp_s);
    if (!scan) {
      refuse_locked(&counts.rejected_unknown_stamp, "an absolute position",
                    "no integrated scan within " +
                        std::to_string(config_.external_stamp_tolerance_s) + " s of " +
                        std::to_string(stamp_s));
      return false;
    }
    SubmapConstraint constraint;
    constraint.kind = SubmapConstraintKind::kAbsolutePosition;
    constraint.from_submap = scan->submap_id;
    constraint.measurement.x = position_world_m.x();
    constraint.measurement.y = position_world_m.y();
    constraint.measurement.z = position_world_m.z();
    constraint.information.topLeftCorner<3, 3>() = 0.5 * (information + information.transpose());
    constraint.lever_arm_m = (scan->T_odom_submap.inverse() * scan->T_odom_sensor).translation();
    pending_constraints_.push_back(constraint);
  }
  submap_queue_.wake();
  return true;
}

bool SlamSystem::add_height(double stamp_s, double height_m, double information_z) {
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    ExternalConstraintCounters& counts = counters_.heights;
    ++counts.received;
    if (!std::isfinite(stamp_s) || !std::isfinite(height_m) || !std::isfinite(information_z) ||
        !(information_z > 0.0)) {
      refuse_locked(&counts.rejected_bad_input, "a height",
                    "the stamp and height must be finite and the information positive, got " +
                        std::to_string(stamp_s) + " s, " + std::to_string(height_m) + " m and " +
                        std::to_string(information_z));
      return false;
    }
    const TrajectoryEntry* scan = scan_near_locked(stamp_s);
    if (!scan) {
      refuse_locked(&counts.rejected_unknown_stamp, "a height",
                    "no integrated scan within " +
                        std::to_string(config_.external_stamp_tolerance_s) + " s of " +
                        std::to_string(stamp_s));
      return false;
    }
    SubmapConstraint constraint;
    constraint.kind = SubmapConstraintKind::kHeight;
    constraint.from_submap = scan->submap_id;
    constraint.measurement.z = height_m;
    constraint.information(2, 2) = information_z;
    constraint.lever_arm_m = (scan->T_odom_submap.inverse() * scan->T_odom_sensor).translation();
    pending_constraints_.push_back(constraint);
  }
  submap_queue_.wake();
  return true;
}

void SlamSystem::request_optimization() {
  bool threads_running = false;
  bool final = false;
  {
    std::lock_guard<std::mutex> lock(lifecycle_mutex_);
    threads_running = started_ && !stopped_;
    final = stopped_;
  }
  if (threads_running) {
    optimization_requested_ = true;
    submap_queue_.wake();
    return;
  }
  // No backend thread to do it (not started yet, or finished): solve here.
  std::lock_guard<std::mutex> backend_lock(backend_mutex_);
  integrate_pending_constraints_locked(final);
  optimize_locked();
}

void SlamSystem::reset_locked() {
  std::vector<GraphSubmap> discarded;  // freed after the locks are released
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    // Bumped first: whatever the threads hold or find queued from now on is recognised as stale.
    generation_.fetch_add(1);
    counters_.scans_discarded_at_reset += static_cast<int64_t>(sensor_queue_.clear());
    counters_.submaps_discarded_at_reset += static_cast<int64_t>(submap_queue_.clear());
    ++counters_.resets;
    discarded.swap(graph_submaps_);
    store_->clear();
    pose_graph_.clear();
    pending_constraints_.clear();
    joint_pairs_.clear();
    place_recognizer_.clear();
    trajectory_.clear();
    last_summary_ = backend::PoseGraphSolverSummary();
  }
  {
    // The new map's stamps need not follow the old one's (a bag played again).
    std::lock_guard<std::mutex> input_lock(input_mutex_);
    have_last_stamp_ = false;
  }
  optimization_requested_ = false;
}

void SlamSystem::reset() {
  std::lock_guard<std::mutex> backend_lock(backend_mutex_);
  reset_locked();
}

SlamSystem::GraphSubmap SlamSystem::stage_loaded_submap(SubmapSnapshot& snapshot,
                                                        MapIntegrators& integrators,
                                                        double* room_bytes,
                                                        std::vector<uint8_t>* compact) {
  const Stream& stream = integrators.stream();
  const std::string name = "load_submaps: submap " + std::to_string(snapshot.id);
  auto submap =
      std::make_unique<Submap>(snapshot.id, config_.device, config_.map, snapshot.T_world_submap);
  try {
    if (snapshot.encoded.empty()) {
      submap->map().load_blocks(snapshot.blocks, stream);
    } else {
      io::load_encoded_submap(snapshot.encoded, &submap->map(), stream);
    }
  } catch (const std::exception& error) {
    throw Error(name + ": " + error.what());
  }
  std::vector<map::HostBlock>().swap(snapshot.blocks);
  submap->finish(integrators);
  std::unique_ptr<SubmapRegistrationPoints> points;
  if (config_.registration.enabled)
    points = prepare_registration_points(submap->map(), config_.registration, stream);
  auto footprint =
      std::make_unique<backend::SubmapFootprint>(backend::submap_footprint(submap->map()));
  const double bytes = static_cast<double>(submap->map().device_bytes());
  if (bytes <= *room_bytes) {
    *room_bytes -= bytes;
  } else {
    // The file's bytes when they have the system's scale: the same bytes a compaction would give
    // (the codec is idempotent); otherwise the loaded voxels encoded with the system's scale.
    const bool same_scale =
        !snapshot.encoded.empty() &&
        io::validate_encoded_submap(snapshot.encoded.data(), snapshot.encoded.size(), name.c_str())
                .distance_scale_m == map_distance_scale_m();
    *compact = same_scale ? std::move(snapshot.encoded)
                          : io::encode_submap(submap->map(), map_distance_scale_m());
    submap->map().release();
  }
  std::vector<uint8_t>().swap(snapshot.encoded);
  return GraphSubmap{std::move(submap), std::move(points), true, std::make_unique<WallMapCache>(),
                     std::move(footprint)};
}

void SlamSystem::load_submaps(std::vector<SubmapSnapshot> submaps) {
  std::sort(submaps.begin(), submaps.end(),
            [](const SubmapSnapshot& a, const SubmapSnapshot& b) { return a.id < b.id; });
  for (size_t k = 0; k < submaps.size(); ++k) {
    const SubmapSnapshot& snapshot = submaps[k];
    const std::string name = "load_submaps: submap " + std::to_string(snapshot.id);
    if (k > 0 && submaps[k - 1].id == snapshot.id) throw Error(name + " appears twice");
    if (!is_valid_rigid_pose(snapshot.T_world_submap))
      throw Error(name + ": the pose is not a finite rigid transform");
    if (!snapshot.T_world_submap.linear().isApprox(
            gravity_aligned(snapshot.T_world_submap).linear(), 1e-6)) {
      throw Error(name +
                  ": the pose has roll or pitch (submap poses are gravity aligned: x, y, z, yaw)");
    }
  }
  // The heavy part (voxels to the device, ESDF, mesh, registration points) before anything is
  // replaced, on this thread with its own integrators: a bad submap leaves the map as it was.
  // The old map's resident submaps stay until the reset, so the new ones may use what is left of
  // the device budget; past it they are released to their compact forms as they are staged.
  MapIntegrators integrators(config_.tsdf, config_.esdf, config_.mesh, Stream(config_.device));
  double room_bytes = std::numeric_limits<double>::infinity();
  if (store_->enabled()) {
    room_bytes = config_.memory.device_budget_mb * 1024.0 * 1024.0 -
                 static_cast<double>(store_->counters().resident_bytes);
  }
  std::vector<GraphSubmap> loaded;
  std::vector<std::vector<uint8_t>> compact_forms(submaps.size());
  loaded.reserve(submaps.size());
  for (size_t k = 0; k < submaps.size(); ++k) {
    loaded.push_back(stage_loaded_submap(submaps[k], integrators, &room_bytes, &compact_forms[k]));
  }

  // New submaps (even one the frontend starts before the reset below) get ids after the loaded
  // ones, so the graph stays in id order.
  if (!submaps.empty()) {
    const int64_t first_free = submaps.back().id + 1;
    int64_t current = next_submap_id_.load();
    while (current < first_free && !next_submap_id_.compare_exchange_weak(current, first_free)) {
    }
  }
  std::lock_guard<std::mutex> backend_lock(backend_mutex_);
  reset_locked();
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (size_t k = 0; k < loaded.size(); ++k) {
      GraphSubmap& entry = loaded[k];
      if (compact_forms[k].empty()) {
        store_->add(*entry.submap);
      } else {
        store_->add_compact(*entry.submap, std::move(compact_forms[k]));
      }
      pose_graph_.add_submap(entry.submap->id(), entry.submap->pose(), /*loaded=*/true);
      graph_submaps_.push_back(std::move(entry));
    }
    counters_.submaps_loaded += static_cast<int64_t>(loaded.size());
  }
  enforce_budget_locked(-1);
}

Eigen::Isometry3d SlamSystem::T_world_odom() const {
  std::lock_guard<std::mutex> lock(state_mutex_);
  for (auto it = graph_submaps_.rbegin(); it != graph_submaps_.rend(); ++it) {
    if (it->loaded) break;
    return it->submap->T_world_submap() * it->submap->T_odom_submap().inverse();
  }
  return Eigen::Isometry3d::Identity();
}

}  // namespace pipeline
}  // namespace covox

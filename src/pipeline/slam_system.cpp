#include "covoxslam/pipeline/slam_system.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <optional>
#include <string>
#include <utility>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/scan_deskew.h"
#include "covoxslam/core/log.h"
#include "covoxslam/core/memory.h"
#include "covoxslam/core/stage_profiler.h"

namespace covox {
namespace pipeline {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

void require(bool condition, const std::string& message) {
  if (!condition) throw Error("SLAM configuration: " + message);
}

// Logs the first drop of a kind and then every 1000th, so a broken sensor cannot flood the log
// while the counters still say exactly how many were dropped.
bool should_log_drop(int64_t count_after) { return count_after == 1 || count_after % 1000 == 0; }

}  // namespace

void validate(const SlamConfig& config) {
  require(std::isfinite(config.map.voxel_size_m) && config.map.voxel_size_m > 0.0f,
          "map.voxel_size_m must be positive, got " + std::to_string(config.map.voxel_size_m));
  require(config.map.voxels_per_side == 8 || config.map.voxels_per_side == 16,
          "map.voxels_per_side must be 8 or 16, got " + std::to_string(config.map.voxels_per_side));
  validate(config.tsdf, config.map.voxel_size_m);
  validate(config.submaps);
  require(std::isfinite(config.deskew.sweep_duration_s) && config.deskew.sweep_duration_s > 0.0,
          "deskew.sweep_duration_s must be positive, got " +
              std::to_string(config.deskew.sweep_duration_s));
  require(config.sensor_queue_size >= 1, "queues.sensor_scans must be at least 1");
  require(config.submap_queue_size >= 1, "queues.submaps must be at least 1");
  require(std::isfinite(config.odometry_translation_sigma_vox) &&
              config.odometry_translation_sigma_vox > 0.0,
          "pose_graph.odometry_translation_sigma_vox must be positive, got " +
              std::to_string(config.odometry_translation_sigma_vox));
  require(std::isfinite(config.odometry_yaw_sigma_rad) && config.odometry_yaw_sigma_rad > 0.0,
          "pose_graph.odometry_yaw_sigma_rad must be positive, got " +
              std::to_string(config.odometry_yaw_sigma_rad));
  require(std::isfinite(config.optimize_spacing_fraction) &&
              config.optimize_spacing_fraction >= 0.0 && config.optimize_spacing_fraction <= 1.0,
          "pose_graph.optimize_spacing_fraction must be in [0, 1], got " +
              std::to_string(config.optimize_spacing_fraction));
  require(config.optimize_every_n_submaps >= 0,
          "pose_graph.optimize_every_n_submaps must be >= 0, got " +
              std::to_string(config.optimize_every_n_submaps));
  require(
      std::isfinite(config.external_stamp_tolerance_s) && config.external_stamp_tolerance_s >= 0.0,
      "pose_graph.external_stamp_tolerance_s must be >= 0, got " +
          std::to_string(config.external_stamp_tolerance_s));
  require(config.max_solves_per_new_submap >= 1,
          "pose_graph.max_solves_per_new_submap must be at least 1, got " +
              std::to_string(config.max_solves_per_new_submap));
  require(std::isfinite(config.revisit_drift_min_path_m) && config.revisit_drift_min_path_m >= 0.0,
          "pose_graph.revisit_drift_min_path_m must be >= 0, got " +
              std::to_string(config.revisit_drift_min_path_m));
  require(std::isfinite(config.min_odometry_drift_m_per_m) &&
              config.min_odometry_drift_m_per_m > 0.0 &&
              std::isfinite(config.min_odometry_drift_deg_per_m) &&
              config.min_odometry_drift_deg_per_m > 0.0,
          "pose_graph.min_odometry_drift_m_per_m and _deg_per_m must be positive");
  validate(config.registration);
  validate(config.memory);
  validate(config.place_recognition);
  if (config.device == Device::kCuda && !cuda_device_available()) {
    throw NotAvailableError(
        "SLAM configuration: device cuda was asked for but no usable GPU is available "
        "(use device auto or cpu)");
  }
}

int64_t submaps_between_optimizations(const SlamConfig& config, int64_t graph_submaps) {
  const int64_t every = config.optimize_every_n_submaps;
  if (every <= 0) return 0;
  const double spaced = std::floor(config.optimize_spacing_fraction *
                                   static_cast<double>(std::max<int64_t>(graph_submaps, 0)));
  return std::max(every, static_cast<int64_t>(spaced));
}

namespace {
// An encoded mesh keeps its vertices on a grid of 1/256 voxel: far finer than the surface that
// marching cubes interpolates from the quantised TSDF.
constexpr float kMeshStepsPerVoxel = 256.0f;

// Validates before any member is built, so a bad configuration fails with its own message.
const SlamConfig& validated(const SlamConfig& config) {
  validate(config);
  return config;
}
}  // namespace

SlamSystem::SlamSystem(const SlamConfig& config)
    : config_(validated(config)),
      sensor_queue_(config.sensor_queue_size, "sensor queue"),
      submap_queue_(config.submap_queue_size, "submap queue"),
      frontend_integrators_(config.tsdf, config.esdf, config.mesh, Stream::create(config.device)),
      points_buffer_(config.device),
      colors_buffer_(config.device),
      times_buffer_(config.device),
      store_(std::make_unique<SubmapStore>(config.memory, config.tsdf.truncation_distance_m,
                                           config.map.voxel_size_m / kMeshStepsPerVoxel)),
      restore_esdf_(config.esdf),
      restore_stream_(Stream::create(config.device)),
      backend_integrators_(config.tsdf, config.esdf, config.mesh, Stream::create(config.device)),
      optimizer_(config),
      place_recognizer_(config.place_recognition) {
  if (config_.device == Device::kCuda) {
    set_device_memory_cache_limit(static_cast<size_t>(config_.memory.device_cache_mb * 1048576.0));
  }
  if (config_.start_threads) start();
}

SlamSystem::~SlamSystem() { shutdown(); }

void SlamSystem::start() {
  std::lock_guard<std::mutex> lock(lifecycle_mutex_);
  if (started_ || stopped_) return;
  started_ = true;
  running_ = true;
  frontend_thread_ = std::thread([this] { frontend_loop(); });
  backend_thread_ = std::thread([this] { backend_loop(); });
}

bool SlamSystem::add_scan(Scan scan) {
  // Checks that need no ordering with other callers.
  const char* problem = nullptr;
  int64_t* counter = nullptr;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.scans_received;
  }
  if (!accepting_.load()) {
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.scans_rejected_not_running;
    return false;
  }
  {
    std::lock_guard<std::mutex> input_lock(input_mutex_);
    if (!std::isfinite(scan.stamp_s) || (have_last_stamp_ && !(scan.stamp_s > last_stamp_s_))) {
      problem = "its stamp is not finite or not after the previous scan's";
      counter = &counters_.scans_dropped_bad_stamp;
    } else if (!is_valid_rigid_pose(scan.T_odom_sensor)) {
      problem = "its odometry pose is not a finite rigid transform";
      counter = &counters_.scans_dropped_invalid_pose;
    } else if (scan.points_sensor_m.empty()) {
      problem = "it has no points";
      counter = &counters_.scans_dropped_empty_cloud;
    } else if (!scan.colors.empty() && scan.colors.size() != scan.points_sensor_m.size()) {
      problem = "its colour count does not match its point count";
      counter = &counters_.scans_dropped_bad_colors;
    } else if ((problem = point_times_problem(scan)) != nullptr) {
      counter = &counters_.scans_dropped_bad_point_times;
    }
    if (!problem) {
      have_last_stamp_ = true;
      last_stamp_s_ = scan.stamp_s;
    }
  }
  if (problem) {
    int64_t count_after = 0;
    {
      std::lock_guard<std::mutex> lock(state_mutex_);
      count_after = ++*counter;
    }
    if (should_log_drop(count_after)) {
      log_warning("SLAM: dropped the scan at ", scan.stamp_s, " s because ", problem, " (",
                  count_after, " such drops so far)");
    }
    return false;
  }

  std::optional<QueuedScan> dropped;
  QueuedScan queued{std::move(scan), generation_.load()};
  const PushResult result = config_.wait_when_queues_full
                                ? sensor_queue_.push_waiting(std::move(queued))
                                : sensor_queue_.push(std::move(queued), &dropped);
  if (result == PushResult::kRejectedClosed) {
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.scans_rejected_not_running;
    return false;
  }
  if (result == PushResult::kQueuedDroppedOldest) {
    int64_t count_after = 0;
    {
      std::lock_guard<std::mutex> lock(state_mutex_);
      count_after = ++counters_.scans_dropped_queue_full;
    }
    if (should_log_drop(count_after)) {
      log_warning("SLAM: the sensor queue (", config_.sensor_queue_size,
                  " scans) is full: dropped the oldest scan, at ",
                  dropped ? dropped->scan.stamp_s : 0.0, " s (", count_after,
                  " so far); the frontend is slower than the sensor");
    }
  }
  return true;
}

void SlamSystem::finish() {
  std::lock_guard<std::mutex> lock(lifecycle_mutex_);
  if (stopped_) return;
  accepting_ = false;
  if (!started_) {
    started_ = true;
    running_ = true;
    frontend_thread_ = std::thread([this] { frontend_loop(); });
    backend_thread_ = std::thread([this] { backend_loop(); });
  }
  // Closing (not aborting) lets the frontend drain the sensor queue; it then hands over the
  // active submap and closes the submap queue, which the backend drains in turn.
  sensor_queue_.close();
  join_threads();
  // The final optimisation runs even when every submap already triggered one: it is what
  // finish() promises, and external constraints that were still waiting enter the graph here.
  {
    std::lock_guard<std::mutex> backend_lock(backend_mutex_);
    integrate_pending_constraints_locked(/*final=*/true);
    optimize_locked();
  }
  stopped_ = true;
  running_ = false;
}

bool SlamSystem::resume() {
  std::lock_guard<std::mutex> lock(lifecycle_mutex_);
  if (aborted_.load()) return false;
  if (!stopped_) return true;
  // finish() left both queues closed and drained and the threads joined; the frontend reset its
  // active submap, so the first scan from now on opens a new one.
  sensor_queue_.reopen();
  submap_queue_.reopen();
  stopped_ = false;
  running_ = true;
  accepting_ = true;
  frontend_thread_ = std::thread([this] { frontend_loop(); });
  backend_thread_ = std::thread([this] { backend_loop(); });
  return true;
}

void SlamSystem::shutdown() {
  std::lock_guard<std::mutex> lock(lifecycle_mutex_);
  if (stopped_) return;
  accepting_ = false;
  aborted_ = true;
  const int64_t queued_scans = static_cast<int64_t>(sensor_queue_.abort());
  submap_queue_.abort();
  join_threads();
  {
    std::lock_guard<std::mutex> state_lock(state_mutex_);
    counters_.scans_discarded_at_shutdown += queued_scans;
  }
  stopped_ = true;
  running_ = false;
}

void SlamSystem::join_threads() {
  if (frontend_thread_.joinable()) frontend_thread_.join();
  if (backend_thread_.joinable()) backend_thread_.join();
}

// ---- Frontend
// ------------------------------------------------------------------------------------

void SlamSystem::frontend_loop() {
  QueuedScan queued;
  double waited_s = 0.0;
  for (;;) {
    const PopResult popped = sensor_queue_.pop_or_wake(&queued, &waited_s);
    if (popped == PopResult::kFinished) break;
    if (popped == PopResult::kWoken) {
      // Idle: esdf_slice_active_submap() asked for a copy of the active submap.
      copy_active_submap_for_slice();
      continue;
    }
    {
      std::lock_guard<std::mutex> lock(state_mutex_);
      timings_.sensor_queue_wait.add(waited_s);
    }
    if (queued.generation != generation_.load()) {
      std::lock_guard<std::mutex> lock(state_mutex_);
      ++counters_.scans_discarded_at_reset;
      continue;
    }
    try {
      process_scan(queued);
    } catch (const std::exception& error) {
      int64_t count_after = 0;
      {
        std::lock_guard<std::mutex> lock(state_mutex_);
        count_after = ++counters_.scans_failed;
      }
      if (should_log_drop(count_after)) {
        log_error("SLAM frontend: integrating the scan at ", queued.scan.stamp_s,
                  " s failed: ", error.what());
      }
    }
    copy_active_submap_for_slice();
    if (aborted_.load()) break;
  }
  if (!aborted_.load()) {
    try {
      hand_over_active_submap();
    } catch (const std::exception& error) {
      log_error("SLAM frontend: handing over the last submap failed: ", error.what());
    }
  }
  active_submap_.reset();
  submap_queue_.close();
}

void SlamSystem::process_scan(const QueuedScan& queued) {
  const Scan& scan = queued.scan;
  if (active_submap_ && active_generation_ != queued.generation) {
    // The map was reset since this submap began: it belongs to the discarded map.
    active_submap_.reset();
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.submaps_discarded_at_reset;
  }
  const Eigen::Vector3d position_m = scan.T_odom_sensor.translation();
  if (active_submap_) {
    const double step_m = (position_m - last_position_odom_m_).norm();
    if (should_start_new_submap(config_.submaps, active_submap_->statistics(), scan.stamp_s,
                                step_m)) {
      hand_over_active_submap();
    }
  }
  if (!active_submap_) {
    const Eigen::Isometry3d T_odom_submap = gravity_aligned(scan.T_odom_sensor);
    active_submap_ = std::make_unique<Submap>(next_submap_id_.fetch_add(1), config_.device,
                                              config_.map, T_odom_submap);
    active_generation_ = queued.generation;
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.submaps_created;
  }

  const auto start = Clock::now();
  const integrators::IntegrationStats stats = integrate_scan(scan);
  const double integrate_s = seconds_since(start);
  last_position_odom_m_ = position_m;

  std::lock_guard<std::mutex> lock(state_mutex_);
  if (queued.generation != generation_.load()) {
    // reset() ran while this scan was integrated: it went into the discarded map.
    ++counters_.scans_discarded_at_reset;
    return;
  }
  timings_.tsdf.add(integrate_s);
  if (scan_durations_s_.size() == kScanDurationsKept) scan_durations_s_.pop_front();
  scan_durations_s_.push_back(integrate_s);
  ++counters_.scans_integrated;
  counters_.points_integrated += stats.points_in;
  counters_.points_dropped_by_integrator += stats.dropped_total();
  trajectory_.push_back(TrajectoryEntry{scan.stamp_s, active_submap_->id(), scan.T_odom_sensor,
                                        active_submap_->T_odom_submap()});
}

integrators::IntegrationStats SlamSystem::integrate_scan(const Scan& scan) {
  const DeskewPlan deskew = plan_deskew(config_.deskew, scan);
  const bool deskewed = deskew.outcome == DeskewOutcome::kDeskewed;
  const integrators::PointCloudView view =
      upload_scan(scan, deskew, &points_buffer_, &colors_buffer_, &times_buffer_,
                  frontend_integrators_.stream());
  // Returns when the scan is in the map, before the next scan overwrites the upload buffers.
  const integrators::IntegrationStats stats =
      active_submap_->integrate(frontend_integrators_, view, scan.T_odom_sensor, scan.stamp_s);
  // A cloud without times from a sensor that moved more than a voxel at the longest ray since the
  // previous scan (within a second: the same time line) is smeared, if it came from a spinning
  // LiDAR; a depth camera's frame or a de-skewed keyframe is not, so this is a count and one
  // warning, not an error.
  const bool moving =
      scan.stamp_s - previous_scan_stamp_s_ < 1.0 &&
      motion_displacement_m(previous_T_odom_sensor_, scan.T_odom_sensor,
                            config_.tsdf.max_ray_length_m) > config_.map.voxel_size_m;
  previous_scan_stamp_s_ = scan.stamp_s;
  previous_T_odom_sensor_ = scan.T_odom_sensor;
  int64_t untimed_moving = 0;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    if (deskewed) ++counters_.scans_deskewed;
    if (deskew.outcome == DeskewOutcome::kNoSweepOdometry)
      ++counters_.scans_not_deskewed_no_sweep_odometry;
    if (deskew.outcome == DeskewOutcome::kNoPointTimes && moving)
      untimed_moving = ++counters_.scans_not_deskewed_no_times_moving;
  }
  if (untimed_moving == 1) {
    log_warning("SLAM: the scan at ", scan.stamp_s,
                " s has no per-point times while the sensor moves; its points are integrated as "
                "they are. A spinning LiDAR's clouds are then smeared over the sweep: give the "
                "driver's time field (t or time) to de-skew them (counted in "
                "scans_not_deskewed_no_times_moving; fine for depth cameras and de-skewed clouds)");
  }
  return stats;
}

void SlamSystem::copy_active_submap_for_slice() {
  if (!active_copy_requested_.exchange(false) || !active_submap_) return;
  auto copy = std::make_shared<ActiveSubmapCopy>();
  copy->id = active_submap_->id();
  copy->generation = active_generation_;
  copy->T_odom_submap = active_submap_->T_odom_submap();
  try {
    copy->blocks = active_submap_->map().snapshot();
  } catch (const std::exception& error) {
    log_error("SLAM frontend: copying the active submap for its ESDF slice failed: ", error.what());
    return;
  }
  std::lock_guard<std::mutex> lock(active_copy_mutex_);
  active_copy_ = std::move(copy);
}

void SlamSystem::hand_over_active_submap() {
  if (!active_submap_) return;
  {
    // The submap stops being the active one; its slice is the finished submaps' business now.
    std::lock_guard<std::mutex> lock(active_copy_mutex_);
    active_copy_.reset();
  }
  std::optional<QueuedSubmap> dropped;
  const int64_t id = active_submap_->id();
  QueuedSubmap queued{std::move(active_submap_), active_generation_};
  const PushResult result = config_.wait_when_queues_full
                                ? submap_queue_.push_waiting(std::move(queued))
                                : submap_queue_.push(std::move(queued), &dropped);
  active_submap_.reset();
  if (result == PushResult::kQueued) return;
  if (result == PushResult::kRejectedClosed) {
    // Only during shutdown(): the submap is discarded with everything else.
    return;
  }
  int64_t count_after = 0;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    count_after = ++counters_.submaps_dropped_queue_full;
  }
  log_warning("SLAM: the submap queue (", config_.submap_queue_size,
              " submaps) is full: dropped submap ",
              (dropped && dropped->submap) ? dropped->submap->id() : -1, " to queue submap ", id,
              " (", count_after, " so far); the backend is slower than the frontend");
}

// ---- Backend
// -------------------------------------------------------------------------------------

void SlamSystem::backend_loop() {
  QueuedSubmap item;
  double waited_s = 0.0;
  for (;;) {
    const PopResult popped = submap_queue_.pop_or_wake(&item, &waited_s);
    if (popped == PopResult::kFinished) break;
    bool optimize_now = false;
    if (popped == PopResult::kItem) {
      {
        std::lock_guard<std::mutex> lock(state_mutex_);
        timings_.submap_queue_wait.add(waited_s);
      }
      optimize_now = process_submap(std::move(item));
    }
    if (aborted_.load()) break;
    std::lock_guard<std::mutex> backend_lock(backend_mutex_);
    const int added = integrate_pending_constraints_locked(/*final=*/false);
    if (added > 0 && config_.optimize_every_n_submaps > 0) optimize_now = true;
    if (optimization_requested_.exchange(false)) optimize_now = true;
    if (optimize_now) optimize_locked();
    if (aborted_.load()) break;
  }
}

bool SlamSystem::process_submap(QueuedSubmap item) {
  std::unique_ptr<Submap> submap = std::move(item.submap);
  std::unique_ptr<SubmapRegistrationPoints> points;
  SubmapFinishTimes times;
  double points_s = 0.0;
  if (item.generation != generation_.load()) {
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.submaps_discarded_at_reset;
    return false;
  }
  // Finishing and point extraction touch only this submap: no lock, so reset() need not wait.
  try {
    times = submap->finish(backend_integrators_);
    store_->add(*submap);
    const auto start = Clock::now();
    StageProfiler::Scope profile("submap registration", backend_integrators_.stream());
    if (config_.registration.enabled)
      points = prepare_registration_points(submap->map(), config_.registration,
                                           backend_integrators_.stream());
    profile.mark("points");
    points_s = seconds_since(start);
  } catch (const std::exception& error) {
    store_->remove(submap->id());
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.submaps_failed;
    log_error("SLAM backend: finishing submap ", submap->id(), " failed: ", error.what());
    return false;
  }
  std::lock_guard<std::mutex> backend_lock(backend_mutex_);
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    if (item.generation != generation_.load()) {
      ++counters_.submaps_discarded_at_reset;
      store_->remove(submap->id());
      return false;
    }
    timings_.esdf.add(times.esdf_s);
    timings_.mesh.add(times.mesh_s);
    ++counters_.submaps_finished;
  }
  const auto start = Clock::now();
  const int64_t id = submap->id();
  try {
    StageProfiler::Scope profile("submap registration", backend_integrators_.stream());
    add_to_pose_graph_locked(std::move(submap), std::move(points));
    profile.mark("pose graph");
    enforce_budget_locked(-1);
    profile.mark("budget");
  } catch (const std::exception& error) {
    store_->remove(id);
    std::lock_guard<std::mutex> lock(state_mutex_);
    ++counters_.submaps_failed;
    log_error("SLAM backend: adding a submap to the pose graph failed: ", error.what());
    return false;
  }
  size_t vertices = 0;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    timings_.registration.add(points_s + seconds_since(start));
    vertices = pose_graph_.size();
  }
  const int every = config_.optimize_every_n_submaps;
  const int64_t spacing = submaps_between_optimizations(config_, static_cast<int64_t>(vertices));
  if (spacing <= 0) return false;
  // Up to 1 / optimize_spacing_fraction submaps: every n-th, counted from the first.
  if (spacing == every) return vertices % static_cast<size_t>(every) == 0;
  return vertices < submaps_at_last_optimization_ ||
         vertices - submaps_at_last_optimization_ >= static_cast<size_t>(spacing);
}

Eigen::Matrix4d SlamSystem::odometry_link_information(const SubmapStatistics& previous) const {
  // The per-link sigmas and the drift over the earlier submap's path, as independent variances.
  const double path_m = previous.distance_travelled_m;
  const double drift_m = config_.odometry_drift_m_per_m * path_m;
  const double drift_rad =
      config_.odometry_drift_deg_per_m * path_m * 3.14159265358979323846 / 180.0;
  const double sigma_m = config_.odometry_translation_sigma_vox * config_.map.voxel_size_m;
  const double sigma_rad = config_.odometry_yaw_sigma_rad;
  Eigen::Matrix4d information = Eigen::Matrix4d::Zero();
  information(0, 0) = information(1, 1) = information(2, 2) =
      1.0 / (sigma_m * sigma_m + drift_m * drift_m);
  information(3, 3) = 1.0 / (sigma_rad * sigma_rad + drift_rad * drift_rad);
  return information;
}

RegistrationOdometry SlamSystem::odometry_for_verification(const Submap& submap,
                                                           double path_m) const {
  RegistrationOdometry odometry;
  odometry.known = true;
  odometry.pose = submap.odometry_pose();
  odometry.path_m = path_m;
  odometry.drift_m_per_m = config_.odometry_drift_m_per_m;
  odometry.drift_rad_per_m = config_.odometry_drift_deg_per_m * 3.14159265358979323846 / 180.0;
  return odometry;
}

RegistrationOdometry SlamSystem::list_partners_locked(
    const Submap& submap, bool joint, std::vector<RegistrationPartner>* partners,
    std::vector<RegistrationPartner>* joint_partners) const {
  double path_m = 0.0;  // the odometry's path length from the first mapped submap
  for (const GraphSubmap& earlier : graph_submaps_) {
    RegistrationPartner partner{earlier.submap->id(),
                                &earlier.submap->map(),
                                earlier.submap->pose(),
                                earlier.walls.get(),
                                earlier.registration_points.get(),
                                RegistrationOdometry(),
                                earlier.footprint.get()};
    if (!earlier.loaded) {
      partner.odometry = odometry_for_verification(*earlier.submap, path_m);
      path_m += earlier.submap->statistics().distance_travelled_m;
    }
    // kJoint: pairs with mapped submaps become dense terms; loaded ones stay pairwise.
    if (joint && !earlier.loaded) {
      joint_partners->push_back(partner);
    } else {
      partners->push_back(partner);
    }
  }
  return odometry_for_verification(submap, path_m);
}

void SlamSystem::add_to_pose_graph_locked(std::unique_ptr<Submap> submap,
                                          std::unique_ptr<SubmapRegistrationPoints> points) {
  // The link to the graph so far, and the initial guess.
  SubmapConstraint link;
  bool have_link = false;
  backend::Pose4Dof guess = submap->odometry_pose();
  std::vector<RegistrationPartner> partners, joint_partners;
  RegistrationOdometry own_odometry;
  const bool joint = config_.registration.mode == RegistrationMode::kJoint;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    if (!graph_submaps_.empty()) {
      const GraphSubmap& previous = graph_submaps_.back();
      have_link = true;
      link.from_submap = previous.submap->id();
      link.to_submap = submap->id();
      if (previous.loaded) {
        // The first submap after load_submaps(): nothing measured links it to the loaded map
        // yet. Its odometry frame is taken as the world frame, held by a near-zero-information
        // anchor so that the new chain has a gauge (registration or a loop closure then moves it).
        link.kind = SubmapConstraintKind::kGaugeAnchor;
        link.measurement = relative_pose_4dof(previous.submap->pose(), guess);
        link.information = Eigen::Matrix4d::Identity() * 1e-6;
      } else {
        link.kind = SubmapConstraintKind::kOdometry;
        link.measurement =
            relative_pose_4dof(previous.submap->odometry_pose(), submap->odometry_pose());
        link.information = odometry_link_information(previous.submap->statistics());
        // The previous corrected pose composed with the odometry step, so a new submap starts
        // consistent with the correction found so far rather than at raw odometry.
        guess = compose(previous.submap->pose(), link.measurement);
      }
    }
    own_odometry = list_partners_locked(*submap, joint, &partners, &joint_partners);
  }
  submap->set_pose(guess);

  // Registration reads the earlier submaps without state_mutex_: only holders of backend_mutex_
  // (this thread now) change or replace them.
  RegistrationCounts counts;
  PlaceRecognitionCounts recognition_counts;
  std::vector<SubmapConstraint> registrations;
  std::vector<int64_t> joint_pair_partners;
  StageProfiler::Scope profile("new submap", backend_integrators_.stream());
  auto walls = std::make_unique<WallMapCache>();
  auto footprint =
      std::make_unique<backend::SubmapFootprint>(backend::submap_footprint(submap->map()));
  profile.mark("footprint");
  if (points) {
    const std::vector<const RegistrationPartner*> chosen =
        overlapping_partners(submap->map(), guess, partners, config_.registration, footprint.get());
    profile.mark("choose partners");
    acquire_partners_locked(chosen);
    profile.mark("partners back");
    registrations = registration_constraints_with(
        submap->id(), submap->map(), *points, guess, chosen, config_.registration,
        backend_integrators_.stream(), &counts, walls.get(), own_odometry);
    profile.mark("registration");
    if (config_.registration.enabled) {
      for (const RegistrationPartner* partner : overlapping_partners(
               submap->map(), guess, joint_partners, config_.registration, footprint.get())) {
        joint_pair_partners.push_back(partner->id);
      }
    }
    propose_place_recognition_locked(*submap, *points, guess, partners, joint_partners,
                                     joint_pair_partners, walls.get(), own_odometry, &registrations,
                                     &recognition_counts);
  }

  std::lock_guard<std::mutex> lock(state_mutex_);
  pose_graph_.add_submap(submap->id(), guess, /*loaded=*/false);
  if (have_link) {
    pose_graph_.add_constraint(link);
    if (link.kind == SubmapConstraintKind::kOdometry) ++counters_.odometry_constraints;
  }
  for (const SubmapConstraint& c : registrations) pose_graph_.add_constraint(c);
  for (int64_t partner : joint_pair_partners)
    joint_pairs_.push_back(JointPair{submap->id(), partner});
  counts.joint_pairs += static_cast<int64_t>(joint_pair_partners.size());
  counters_.registration.add(counts);
  counters_.place_recognition.add(recognition_counts);
  graph_submaps_.push_back(GraphSubmap{std::move(submap), std::move(points), false,
                                       std::move(walls), std::move(footprint)});
}

void SlamSystem::propose_place_recognition_locked(
    const Submap& submap, const SubmapRegistrationPoints& points, const backend::Pose4Dof& guess,
    const std::vector<RegistrationPartner>& partners,
    const std::vector<RegistrationPartner>& joint_partners,
    const std::vector<int64_t>& joint_pair_partners, WallMapCache* walls,
    const RegistrationOdometry& odometry, std::vector<SubmapConstraint>* registrations,
    PlaceRecognitionCounts* counts) {
  if (!config_.place_recognition.enabled) return;
  std::vector<RegistrationPartner> earlier = partners;
  earlier.insert(earlier.end(), joint_partners.begin(), joint_partners.end());
  std::vector<int64_t> linked = joint_pair_partners;
  for (const SubmapConstraint& c : *registrations) linked.push_back(c.from_submap);
  std::vector<int64_t> earlier_ids;
  for (const RegistrationPartner& partner : earlier) earlier_ids.push_back(partner.id);
  const std::vector<PlaceCandidate> candidates =
      place_recognizer_.search(submap.id(), submap.map(), submap_path_locked(submap), earlier_ids,
                               linked, backend_integrators_.stream(), counts);
  // The candidates were found from their descriptors alone: their maps may be compact or on disk.
  std::vector<const RegistrationPartner*> wanted;
  for (const PlaceCandidate& candidate : candidates) {
    for (const RegistrationPartner& partner : earlier) {
      if (partner.id == candidate.id) wanted.push_back(&partner);
    }
  }
  acquire_partners_locked(wanted);
  const std::vector<VerifiedClosure> verified = place_recognizer_.verify(
      submap.id(), submap.map(), points, guess, candidates, earlier, config_.registration,
      backend_integrators_.stream(), walls, odometry, counts);
  for (const SubmapConstraint& c : place_recognizer_.confirm(submap.id(), verified, counts)) {
    registrations->push_back(c);
  }
}

std::vector<Eigen::Vector2d> SlamSystem::submap_path_locked(const Submap& submap) {
  // The submap's scans are the latest entries of trajectory_ before those of newer submaps.
  const Eigen::Isometry3d T_submap_odom = submap.T_odom_submap().inverse();
  std::vector<Eigen::Vector2d> path_m;
  std::lock_guard<std::mutex> lock(state_mutex_);
  for (auto it = trajectory_.rbegin(); it != trajectory_.rend(); ++it) {
    if (it->submap_id > submap.id()) continue;
    if (it->submap_id < submap.id()) break;
    path_m.push_back((T_submap_odom * it->T_odom_sensor.translation()).head<2>());
  }
  std::reverse(path_m.begin(), path_m.end());
  return path_m;
}

int SlamSystem::integrate_pending_constraints_locked(bool final) {
  std::lock_guard<std::mutex> lock(state_mutex_);
  int added = 0;
  std::vector<SubmapConstraint> still_waiting;
  const int64_t last_id = pose_graph_.last_id();
  for (const SubmapConstraint& c : pending_constraints_) {
    const bool from_in = pose_graph_.contains(c.from_submap);
    const bool to_in = c.is_absolute() || pose_graph_.contains(c.to_submap);
    ExternalConstraintCounters& counts = external_counters_locked(c.kind);
    if (from_in && to_in) {
      pose_graph_.add_constraint(c);
      ++counts.added;
      ++added;
      continue;
    }
    // Submaps enter in id order: one at or below the last id that is missing never will.
    const bool lost = final || (!from_in && c.from_submap <= last_id) ||
                      (!c.is_absolute() && !to_in && c.to_submap <= last_id);
    if (lost) {
      ++counts.dropped_submap_lost;
      log_warning("SLAM backend: dropped a ", to_string(c.kind),
                  " constraint: its submap never reached the graph");
    } else {
      still_waiting.push_back(c);
    }
  }
  pending_constraints_.swap(still_waiting);
  return added;
}

// The SLAM system's pose graph as the optimiser sees it (graph_optimizer.h); the caller holds
// backend_mutex_, and each call takes state_mutex_ for itself.
class SlamSystem::GraphAccess : public OptimizedGraph {
 public:
  explicit GraphAccess(SlamSystem& system) : system_(system) {}

  void edit(const std::function<void(SubmapPoseGraph&)>& change) override {
    std::lock_guard<std::mutex> lock(system_.state_mutex_);
    change(system_.pose_graph_);
  }

  SolverInput solver_input() override {
    std::lock_guard<std::mutex> lock(system_.state_mutex_);
    SolverInput input;
    input.graph = system_.pose_graph_.to_backend_graph();
    input.terms = system_.joint_terms_locked(input.graph);
    for (const SubmapConstraint& c : system_.pose_graph_.constraints())
      input.has_absolute = input.has_absolute || c.is_absolute();
    return input;
  }

  void apply(const SubmapPoseGraph::BackendGraph& solved,
             const backend::PoseGraphSolverSummary& summary, double solve_s) override {
    std::lock_guard<std::mutex> lock(system_.state_mutex_);
    system_.timings_.backend.add(solve_s);
    ++system_.counters_.optimizations;
    system_.last_summary_ = summary;
    system_.pose_graph_.apply_solution(solved);
    for (size_t k = 0; k < system_.graph_submaps_.size(); ++k)
      system_.graph_submaps_[k].submap->set_pose(system_.pose_graph_.nodes()[k].pose);
    system_.update_correction_counters_locked();
  }

  std::vector<double> path_at_node_m() override {
    std::lock_guard<std::mutex> lock(system_.state_mutex_);
    const std::vector<GraphSubmap>& submaps = system_.graph_submaps_;
    std::vector<double> path_m(submaps.size(), 0.0);
    for (size_t k = 1; k < submaps.size(); ++k)
      path_m[k] = path_m[k - 1] + submaps[k - 1].submap->statistics().distance_travelled_m;
    return path_m;
  }

 private:
  SlamSystem& system_;
};

void SlamSystem::optimize_locked() {
  int64_t new_submaps = 0;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    new_submaps = static_cast<int64_t>(pose_graph_.size()) -
                  static_cast<int64_t>(std::min(submaps_at_last_optimization_, pose_graph_.size()));
    submaps_at_last_optimization_ = pose_graph_.size();
  }
  GraphAccess graph(*this);
  const OptimizationReport report = optimizer_.optimize(graph, new_submaps);
  std::lock_guard<std::mutex> lock(state_mutex_);
  counters_.optimizations_failed += report.failed_solves;
  if (report.budget_exhausted) ++counters_.optimizations_over_budget;
  if (report.gate_finished) counters_.registrations_set_aside = report.set_aside;
  if (report.noise_estimated) {
    counters_.odometry_drift_estimate_m_per_m = report.odometry_drift_m_per_m;
    counters_.odometry_drift_estimate_deg_per_m = report.odometry_drift_deg_per_m;
    counters_.revisits_measuring_drift = report.revisits.revisits;
    counters_.revisit_drift_m_per_m = report.revisits.m_per_m;
    counters_.revisit_drift_deg_per_m = report.revisits.rad_per_m * 180.0 / 3.14159265358979323846;
  }
}

void SlamSystem::update_correction_counters_locked() {
  double sum_sq = 0.0, largest = 0.0;
  int64_t count = 0;
  for (const GraphSubmap& g : graph_submaps_) {
    if (g.loaded) continue;
    const backend::Pose4Dof& a = g.submap->pose();
    const backend::Pose4Dof& b = g.submap->odometry_pose();
    const double d = std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) +
                               (a.z - b.z) * (a.z - b.z));
    sum_sq += d * d;
    largest = std::max(largest, d);
    ++count;
  }
  counters_.correction_rms_m = count > 0 ? std::sqrt(sum_sq / static_cast<double>(count)) : 0.0;
  counters_.correction_max_m = largest;
}

std::vector<backend::RegistrationTerm> SlamSystem::joint_terms_locked(
    const SubmapPoseGraph::BackendGraph& graph) const {
  std::vector<backend::RegistrationTerm> terms;
  for (const JointPair& pair : joint_pairs_) {
    const int64_t index_i = pose_graph_.index_of(pair.points_submap);
    const int64_t index_j = pose_graph_.index_of(pair.field_submap);
    if (index_i < 0 || index_j < 0) continue;
    const GraphSubmap& points_submap = graph_submaps_[static_cast<size_t>(index_i)];
    const GraphSubmap& field_submap = graph_submaps_[static_cast<size_t>(index_j)];
    if (!points_submap.registration_points) continue;
    backend::RegistrationTerm term;
    term.vertex_i = graph.vertex_of_node[static_cast<size_t>(index_i)];
    term.vertex_j = graph.vertex_of_node[static_cast<size_t>(index_j)];
    if (term.vertex_i == term.vertex_j) continue;
    term.points_i = &points_submap.registration_points->points;
    term.map_j = &field_submap.submap->map();
    // The same scaling as the pairwise constraints (registration_constraints.h): weights
    // normalised to mean 1, point_sigma_m and the loss scale in metres.
    const double sqrt_mean_weight = std::sqrt(points_submap.registration_points->mean_weight);
    term.residual.distance = config_.registration.alignment.distance;
    term.residual.loss = config_.registration.alignment.robust_loss;
    term.residual.loss_scale =
        config_.registration.alignment.robust_loss_scale_m * sqrt_mean_weight;
    term.residual_sigma = config_.registration.information.point_sigma_m * sqrt_mean_weight;
    terms.push_back(term);
  }
  return terms;
}

// ---- Accessors
// -----------------------------------------------------------------------------------

Eigen::Isometry3d SlamSystem::correction_for_locked(int64_t submap_id) const {
  // graph_submaps_ is in id order (the queues preserve order); the latest submap at or before
  // `submap_id` carries the correction that applies to its scans.
  auto after =
      std::upper_bound(graph_submaps_.begin(), graph_submaps_.end(), submap_id,
                       [](int64_t id, const GraphSubmap& s) { return id < s.submap->id(); });
  if (after == graph_submaps_.begin()) return Eigen::Isometry3d::Identity();
  const Submap& reference = *(after - 1)->submap;
  return reference.T_world_submap() * reference.T_odom_submap().inverse();
}

std::vector<SubmapInfo> SlamSystem::submaps() const {
  std::lock_guard<std::mutex> lock(state_mutex_);
  std::vector<SubmapInfo> infos;
  infos.reserve(graph_submaps_.size());
  for (const GraphSubmap& entry : graph_submaps_) {
    const Submap& submap = *entry.submap;
    SubmapInfo info;
    info.id = submap.id();
    info.T_world_submap = submap.T_world_submap();
    info.T_odom_submap = submap.T_odom_submap();
    info.statistics = submap.statistics();
    info.bounding_box_world = submap.bounding_box_world();
    info.mesh_triangles = submap.mesh_triangles();
    info.loaded = entry.loaded;
    infos.push_back(info);
  }
  return infos;
}

std::vector<StampedPose> SlamSystem::corrected_trajectory() const {
  std::lock_guard<std::mutex> lock(state_mutex_);
  std::vector<StampedPose> trajectory;
  trajectory.reserve(trajectory_.size());
  for (const TrajectoryEntry& entry : trajectory_) {
    const Eigen::Isometry3d correction = correction_for_locked(entry.submap_id);
    if (config_.interpolate_trajectory_correction) {
      // The scan's own submap in the graph and the one after it (graph_submaps_ is in id order).
      auto after =
          std::upper_bound(graph_submaps_.begin(), graph_submaps_.end(), entry.submap_id,
                           [](int64_t id, const GraphSubmap& s) { return id < s.submap->id(); });
      if (after != graph_submaps_.begin() && after != graph_submaps_.end()) {
        const Submap& own = *(after - 1)->submap;
        const Submap& next = *after->submap;
        const double start_s = own.statistics().start_stamp_s;
        const double next_start_s = next.statistics().start_stamp_s;
        if (own.id() == entry.submap_id && !(after - 1)->loaded && !after->loaded &&
            next.statistics().scans > 0 && next_start_s > start_s) {
          const Eigen::Isometry3d next_correction =
              next.T_world_submap() * next.T_odom_submap().inverse();
          const double alpha = (entry.stamp_s - start_s) / (next_start_s - start_s);
          trajectory.push_back(StampedPose{
              entry.stamp_s,
              blend_corrected_pose(correction, next_correction, entry.T_odom_sensor, alpha)});
          continue;
        }
      }
    }
    trajectory.push_back(StampedPose{entry.stamp_s, correction * entry.T_odom_sensor});
  }
  return trajectory;
}

map::Mesh SlamSystem::combined_mesh() const {
  std::vector<std::pair<int64_t, Eigen::Isometry3f>> submaps;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const GraphSubmap& entry : graph_submaps_)
      submaps.emplace_back(entry.submap->id(), entry.submap->T_world_submap().cast<float>());
  }
  map::Mesh combined;
  map::Mesh mesh;
  for (const auto& [id, T_world_submap] : submaps) {
    // The store holds the meshes under its own lock; one removed since (a reset) is skipped.
    if (!store_->mesh(id, &mesh)) continue;
    const uint32_t offset = static_cast<uint32_t>(combined.vertices_m.size());
    for (const Vec3f& v : mesh.vertices_m) {
      const Eigen::Vector3f p = T_world_submap * Eigen::Vector3f(v.x, v.y, v.z);
      combined.vertices_m.emplace_back(p.x(), p.y(), p.z());
    }
    // Colours stay per vertex; a submap without colours gets grey so the arrays stay aligned.
    if (mesh.colors.size() == mesh.vertices_m.size()) {
      combined.colors.insert(combined.colors.end(), mesh.colors.begin(), mesh.colors.end());
    } else {
      combined.colors.insert(combined.colors.end(), mesh.vertices_m.size(), Rgb8{128, 128, 128});
    }
    for (uint32_t index : mesh.triangles) combined.triangles.push_back(index + offset);
  }
  return combined;
}

SlamCounters SlamSystem::counters() const {
  const SubmapStoreCounters memory = store_->counters();
  std::lock_guard<std::mutex> lock(state_mutex_);
  SlamCounters counters = counters_;
  counters.memory = memory;
  return counters;
}

SlamTimings SlamSystem::timings() const {
  std::lock_guard<std::mutex> lock(state_mutex_);
  return timings_;
}

std::vector<double> SlamSystem::take_scan_durations() {
  std::lock_guard<std::mutex> lock(state_mutex_);
  std::vector<double> taken(scan_durations_s_.begin(), scan_durations_s_.end());
  scan_durations_s_.clear();
  return taken;
}

backend::PoseGraphSolverSummary SlamSystem::last_solver_summary() const {
  std::lock_guard<std::mutex> lock(state_mutex_);
  return last_summary_;
}

std::vector<SubmapConstraint> SlamSystem::constraints() const {
  std::lock_guard<std::mutex> lock(state_mutex_);
  return pose_graph_.constraints();
}

}  // namespace pipeline
}  // namespace covox

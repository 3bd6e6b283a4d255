#pragma once
// SlamSystem: the pure C++ SLAM pipeline (no ROS), DESIGN.md "The data path".
//
//   add_scan() ──► sensor queue ──► frontend thread: integrate each scan into the active submap
//                                   at its odometry pose in the submap frame; the creation
//                                   policy decides when the active submap is handed over
//                  submap queue ◄──┘
//                       │
//                       ▼
//                  backend thread: finish the submap (ESDF, mesh, bounding box), add an odometry
//                                  constraint to the previous submap, optimise the 4-DoF graph
//
// Both queues are bounded (sizes are parameters). The frontend never waits for the backend and
// the caller never waits for the frontend: a full queue drops its OLDEST entry and counts it.
// Bad input (non-finite or non-rigid pose, empty cloud, stamp not increasing, colour count not
// matching the point count) is counted and dropped, never thrown.
//
// Lifecycle: the threads start in the constructor (or in start() when config.start_threads is
// false). finish() flushes both queues - every queued scan is integrated, the active submap is
// handed over and finished - and runs a final optimisation. shutdown() (and the destructor) stop
// at once and discard queued work. After either, add_scan() is refused (counted).
//
// Until registration and loop-closure constraints exist, the graph holds only odometry
// constraints, so the corrected poses equal the odometry poses.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/map/tsdf_map.h"
#include "covoxslam/pipeline/bounded_queue.h"
#include "covoxslam/pipeline/submap.h"

namespace covox {
namespace pipeline {

struct SlamConfig {
  Device device = Device::kCpu;
  TsdfMapConfig map;
  TsdfIntegratorConfig tsdf;
  EsdfIntegratorConfig esdf;
  MeshIntegratorConfig mesh;
  SubmapPolicyConfig submaps;
  // Scans waiting for the frontend; at 10 Hz, 20 scans absorb a 2 s stall of the frontend.
  size_t sensor_queue_size = 20;
  // Submaps waiting for the backend (each holds its whole TSDF: keep this small).
  size_t submap_queue_size = 4;
  // Standard deviations of the odometry between consecutive submaps (information = 1 / sigma^2).
  double odometry_translation_sigma_m = 0.1;
  double odometry_yaw_sigma_rad = 0.01;
  // Optimise after every n-th submap enters the graph; 0: only in finish().
  int optimize_every_n_submaps = 1;
  backend::PoseGraphSolverOptions solver;
  // False: the threads start in start(), so that tests can fill the queues first.
  bool start_threads = true;
};

// Throws covox::Error naming the first invalid parameter.
void validate(const SlamConfig& config);

// One scan: points in the sensor frame and the sensor's odometry pose at the scan's stamp.
struct Scan {
  double stamp_s = 0.0;
  Eigen::Isometry3d T_odom_sensor = Eigen::Isometry3d::Identity();
  std::vector<Vec3f> points_sensor_m;
  std::vector<Rgb8> colors;  // empty, or one per point
};

struct SlamCounters {
  // Input side (add_scan and the sensor queue).
  int64_t scans_received = 0;                // every add_scan call
  int64_t scans_dropped_invalid_pose = 0;    // non-finite or non-rigid T_odom_sensor
  int64_t scans_dropped_empty_cloud = 0;
  int64_t scans_dropped_bad_stamp = 0;       // non-finite, or not after the previous scan's
  int64_t scans_dropped_bad_colors = 0;      // colour count not matching the point count
  int64_t scans_rejected_not_running = 0;    // after finish() or shutdown()
  int64_t scans_dropped_queue_full = 0;      // oldest scans dropped by the sensor queue
  int64_t scans_discarded_at_shutdown = 0;   // still queued when shutdown() ran
  // Frontend.
  int64_t scans_integrated = 0;
  int64_t scans_failed = 0;                  // the integrator threw (logged)
  int64_t points_integrated = 0;             // points handed to the integrator
  int64_t points_dropped_by_integrator = 0;  // non-finite, too close or too far
  int64_t submaps_created = 0;
  int64_t submaps_dropped_queue_full = 0;    // oldest submaps dropped by the submap queue
  // Backend.
  int64_t submaps_finished = 0;
  int64_t submaps_failed = 0;                // finishing threw (logged)
  int64_t odometry_constraints = 0;
  int64_t optimizations = 0;
  int64_t optimizations_failed = 0;

  // Every scan that was given but will never be integrated, for any counted reason.
  int64_t scans_dropped_total() const {
    return scans_dropped_invalid_pose + scans_dropped_empty_cloud + scans_dropped_bad_stamp +
           scans_dropped_bad_colors + scans_rejected_not_running + scans_dropped_queue_full +
           scans_discarded_at_shutdown + scans_failed;
  }
};

// Wall time of one module: how often it ran, in total and at worst.
struct ModuleTiming {
  int64_t calls = 0;
  double total_s = 0.0;
  double max_s = 0.0;
  void add(double seconds) {
    ++calls;
    total_s += seconds;
    if (seconds > max_s) max_s = seconds;
  }
  double mean_ms() const { return calls > 0 ? 1000.0 * total_s / calls : 0.0; }
};

struct SlamTimings {
  ModuleTiming tsdf;               // per scan: upload and integration
  ModuleTiming esdf;               // per submap: the whole ESDF when it is finished
  ModuleTiming mesh;               // per submap: marching cubes when it is finished
  ModuleTiming backend;            // per optimisation: the pose-graph solve
  ModuleTiming sensor_queue_wait;  // per scan: time from add_scan to the frontend taking it
  ModuleTiming submap_queue_wait;  // per submap: time from hand-over to the backend taking it
};

// One integrated scan with its corrected pose.
struct StampedPose {
  double stamp_s = 0.0;
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
};

// A finished submap's voxels at its corrected pose (what a map file stores; io is a layer below
// pipeline, so the conversion to io::MapFileContents happens in the caller).
struct SubmapSnapshot {
  int64_t id = 0;
  Eigen::Isometry3d T_world_submap = Eigen::Isometry3d::Identity();
  std::vector<HostBlock> blocks;  // TSDF, colour and ESDF, as TsdfMap::snapshot() returns them
};

// A finished submap in the pose graph, as the outside sees it.
struct SubmapInfo {
  int64_t id = 0;
  Eigen::Isometry3d T_world_submap = Eigen::Isometry3d::Identity();  // corrected
  Eigen::Isometry3d T_odom_submap = Eigen::Isometry3d::Identity();   // from odometry
  SubmapStatistics statistics;
  Eigen::AlignedBox3d bounding_box_world;
  int64_t mesh_triangles = 0;
};

class SlamSystem {
 public:
  // Throws covox::Error for an invalid configuration.
  explicit SlamSystem(const SlamConfig& config);
  ~SlamSystem();  // shutdown() unless finish() ran
  SlamSystem(const SlamSystem&) = delete;
  SlamSystem& operator=(const SlamSystem&) = delete;

  const SlamConfig& config() const { return config_; }

  // Starts the threads (only needed with config.start_threads = false; otherwise a no-op).
  void start();
  // Validates and queues a scan; returns false when it was dropped (and counted). Never blocks
  // on the frontend; thread-safe, but stamps must increase across callers.
  bool add_scan(Scan scan);
  // Integrates everything queued, finishes the last submap, runs a final optimisation, and stops
  // the threads. Idempotent. Starts the threads first if start() was never called.
  void finish();
  // Stops the threads at once; queued scans and submaps are discarded (counted). Idempotent.
  void shutdown();
  bool running() const { return running_.load(); }
  // Entries waiting now: for diagnostics, and for offline runners that throttle their input
  // instead of letting the queues drop (a recorded flight should be processed completely).
  size_t sensor_queue_length() const { return sensor_queue_.size(); }
  size_t submap_queue_length() const { return submap_queue_.size(); }

  // Submaps in the pose graph with their corrected poses, in creation order.
  std::vector<SubmapInfo> submaps() const;
  // Every integrated scan's stamp with its corrected pose: T_W_S * T_odom_S^-1 * T_odom_sensor
  // of its submap, or, for a submap not (yet) in the graph, the correction of the latest earlier
  // submap that is (voxgraph's mission-to-odom correction).
  std::vector<StampedPose> corrected_trajectory() const;
  // The finished submaps' meshes moved to their corrected poses, as one mesh.
  Mesh combined_mesh() const;
  // The finished submaps (TSDF, colour, ESDF) at their corrected poses, for saving a map.
  std::vector<SubmapSnapshot> submap_snapshots() const;
  SlamCounters counters() const;
  SlamTimings timings() const;
  // The latest optimisation's summary (default-constructed before the first).
  backend::PoseGraphSolverSummary last_solver_summary() const;

 private:
  struct TrajectoryEntry {
    double stamp_s;
    int64_t submap_id;
    Eigen::Isometry3d T_odom_sensor;
  };

  void frontend_loop();
  void backend_loop();
  void process_scan(const Scan& scan);
  void hand_over_active_submap();
  void add_to_pose_graph(std::unique_ptr<Submap> submap);
  void optimize();
  void join_threads();
  // The correction T_W_odom for scans of submap `submap_id`; needs state_mutex_.
  Eigen::Isometry3d correction_for_locked(int64_t submap_id) const;

  const SlamConfig config_;
  BoundedQueue<Scan> sensor_queue_;
  BoundedQueue<std::unique_ptr<Submap>> submap_queue_;

  // Frontend thread only.
  TsdfIntegrator tsdf_integrator_;
  Stream frontend_stream_;
  Buffer<Vec3f> points_buffer_;
  Buffer<Rgb8> colors_buffer_;
  std::unique_ptr<Submap> active_submap_;
  Eigen::Vector3d last_position_odom_m_ = Eigen::Vector3d::Zero();
  int64_t next_submap_id_ = 0;

  // Backend thread only (and finish() after the threads have joined).
  EsdfIntegrator esdf_integrator_;
  MeshIntegrator mesh_integrator_;
  Stream backend_stream_;

  // Caller side of add_scan.
  std::mutex input_mutex_;
  bool have_last_stamp_ = false;
  double last_stamp_s_ = 0.0;

  // Lifecycle.
  std::mutex lifecycle_mutex_;
  std::thread frontend_thread_;
  std::thread backend_thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> accepting_{true};
  std::atomic<bool> aborted_{false};
  bool started_ = false;
  bool stopped_ = false;

  // Shared state read by the accessors.
  mutable std::mutex state_mutex_;
  SlamCounters counters_;
  SlamTimings timings_;
  std::vector<std::unique_ptr<Submap>> graph_submaps_;  // vertex i is graph_submaps_[i]
  backend::PoseGraph4Dof graph_;
  backend::PoseGraphSolverSummary last_summary_;
  std::vector<TrajectoryEntry> trajectory_;
  // T_odom_S of every submap created (also those dropped later), for the trajectory.
  std::vector<Eigen::Isometry3d> created_submap_poses_;
};

}  // namespace pipeline
}  // namespace covox

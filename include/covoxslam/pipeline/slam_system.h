#pragma once
// SlamSystem: the pure C++ SLAM pipeline (no ROS), the data path of docs/design.md: add_scan()
// feeds the sensor queue, a frontend thread integrates each scan into the active submap at its
// odometry pose, the submap queue carries finished submaps to a backend thread that finishes
// them, adds their odometry, registration and waiting external constraints and optimises the
// 4-DoF graph. Both queues are bounded; a full one drops its oldest entry and counts it, so the
// caller never waits; bad input is counted and dropped, never thrown. The threads start in the
// constructor (or start()); finish() flushes and optimises, shutdown() stops at once, and after
// either add_scan() is refused until resume() (after finish()) starts a new submap; reset() and
// load_submaps() replace the map. External constraints name scans by stamp and wait for them.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_set>
#include <vector>

#include <Eigen/Geometry>

#include "covoxslam/backend/pose_graph.h"
#include "covoxslam/backend/pose_graph_solver.h"
#include "covoxslam/backend/registration_terms.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/device.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/core/vec3.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/esdf_queries.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/map/tsdf_map.h"
#include "covoxslam/pipeline/bounded_queue.h"
#include "covoxslam/pipeline/external_constraints.h"
#include "covoxslam/pipeline/graph_optimizer.h"
#include "covoxslam/pipeline/map_integrators.h"
#include "covoxslam/pipeline/place_recognition.h"
#include "covoxslam/pipeline/registration_constraints.h"
#include "covoxslam/pipeline/revisit_drift.h"
#include "covoxslam/pipeline/submap.h"
#include "covoxslam/pipeline/submap_pose_graph.h"
#include "covoxslam/pipeline/submap_store.h"
#include "covoxslam/pipeline/sweep_odometry.h"

namespace covox {
namespace pipeline {

// De-skewing of LiDAR sweeps (pipeline/scan_deskew.h, integrators/sweep_motion.h).
struct DeskewConfig {
  // Points with times are moved to the scan's stamp by the odometry across the sweep.
  bool enabled = true;
  // The sweep's duration, for organised clouds without a time field: their columns are taken as
  // fired in order over this long (a 10 Hz spinning LiDAR: 0.1 s). Read by the cloud decoders.
  double sweep_duration_s = 0.1;
};

// Every field is a parameter of the configuration files (pipeline/slam_parameters.h reads them;
// docs/parameters.md lists each with its name, unit and default).
struct SlamConfig {
  Device device = Device::kCpu;
  map::TsdfMapConfig map;
  integrators::TsdfIntegratorConfig tsdf;
  integrators::EsdfIntegratorConfig esdf;
  integrators::MeshIntegratorConfig mesh;
  SubmapPolicyConfig submaps;
  DeskewConfig deskew;
  // Scans waiting for the frontend; at 10 Hz, 20 scans absorb a 2 s stall of the frontend.
  size_t sensor_queue_size = 20;
  // Submaps waiting for the backend (each holds its whole TSDF: keep this small).
  size_t submap_queue_size = 4;
  // False (live input): a full queue drops its oldest entry, counted, so the map keeps up with
  // the robot. True (offline input, the offline runner's): add_scan() and the frontend wait for
  // room instead, so nothing is dropped and the result does not depend on the machine's speed or
  // load (add_scan() then needs the threads running).
  bool wait_when_queues_full = false;
  // Standard deviations of the odometry between consecutive submaps (information = 1 / sigma^2),
  // added to the drift below: the part that does not grow with the path (a keyframe submap of one
  // scan travels no path of its own). The translation's in voxels of the map, so that it follows
  // the scale the sensor is mapped at (a room at 4 cm: 1 cm; a street at 0.5 m: 12.5 cm). With
  // estimate_odometry_noise scaled alike with the drift.
  double odometry_translation_sigma_vox = 0.25;
  double odometry_yaw_sigma_rad = 0.002;
  // The odometry's drift per metre of path (per axis, and in yaw): two submaps' odometry relative
  // pose is believed to within these times the path between them. The odometry constraint of
  // consecutive submaps gets this drift over the earlier submap's path added to the sigmas above
  // (variances add), and a registration that disagrees with the odometry beyond it is rejected
  // (registration.verification). With estimate_odometry_noise these are the ceiling of the
  // estimate: wide enough for a hand-held camera's visual odometry and for a drone's VIO alike.
  // 0 and 0: the sigmas alone.
  double odometry_drift_m_per_m = 0.1;
  double odometry_drift_deg_per_m = 2.0;
  // True: the odometry's noise is estimated from the data after every optimisation (variance
  // components, estimate_odometry_variance_ratios in submap_pose_graph.h): the odometry's
  // variances in the solve (per-link sigmas and drift alike) are scaled by a factor fitted to its
  // residuals against the registrations, with re-solves until the factor settles. The factor
  // lies between (min_odometry_drift / odometry_drift)^2 and 1: the configured drift is the
  // upper bound and stays what registrations are verified against. Off unless both drifts > 0;
  // a floor above its drift holds the factor at 1.
  bool estimate_odometry_noise = true;
  // The floors keep the estimate from collapsing onto the odometry: once the consistency gate has
  // set registrations aside, the fewer left make the odometry look better than it is.
  double min_odometry_drift_m_per_m = 0.005;
  double min_odometry_drift_deg_per_m = 0.02;
  // estimate_odometry_noise: the drift the revisits show (pipeline/revisit_drift.h: registrations
  // between submaps at least this far apart along the path, against the odometry's relative pose)
  // is a lower bound on the estimate. A per-link estimate sees only each link's own error; a bias
  // that repeats on every link ends a long chain further off than independent errors would, and
  // only a revisit measures that. 0: the per-link estimate alone.
  double revisit_drift_min_path_m = 100.0;
  // Robust loss on registration constraints in the pose-graph solve (Cauchy, by iteratively
  // reweighted solves): a constraint whose whitened residual r (r^2 = e^T information e at the
  // solution) is large gets its information times 1 / (1 + r^2 / c^2), c this scale in standard
  // deviations, so one wrong registration cannot bend the trajectory. 0: plain least squares.
  double registration_loss_scale_sigmas = 3.0;
  // Optimise after every n-th submap enters the graph, and when external constraints or
  // request_optimization() arrive; 0: only in finish() and on request_optimization().
  int optimize_every_n_submaps = 1;
  // Long missions: a solve of the whole graph costs time in proportion to its size, so once the
  // graph holds more than 1 / fraction submaps the optimisations are spaced by fraction x the
  // graph's size (submaps_between_optimizations), which keeps the solve time per new submap
  // bounded. Below that size nothing changes. 0: every n-th submap however large the graph.
  double optimize_spacing_fraction = 1.0 / 32.0;
  // The solve budget of one optimisation (graph_optimizer.h): this many solves per submap that
  // entered the graph since the previous optimisation. The gate's rounds, the robust loss's
  // reweighting and the noise estimation nest solves; past the budget the optimisation stops
  // with its latest solution, counted (optimizations_over_budget).
  int max_solves_per_new_submap = 50;
  // Corrected trajectory: true: a scan between the first scans of submap k and of the next
  // submap in the graph gets the correction blended linearly in time between the two submaps'
  // corrections (blend_corrected_pose), as odometry drift grows over the submap; the last submap
  // keeps its own. False (voxgraph's): every scan of a submap gets its submap's correction
  // T_world_submap * T_odom_submap^-1, a step at each new submap. Only the reported trajectory
  // changes (the maps, constraints and the graph do not).
  bool interpolate_trajectory_correction = true;
  // Registration constraints between overlapping submaps (the drift correction).
  SubmapRegistrationConfig registration;
  // Loop closures by place recognition over finished submaps (pipeline/place_recognition.h).
  PlaceRecognitionConfig place_recognition;
  // Loop closures, GNSS positions and heights name a scan by stamp: the nearest integrated scan
  // within this tolerance (a 10 Hz LiDAR: half the scan period covers every stamp in between).
  double external_stamp_tolerance_s = 0.05;
  backend::PoseGraphSolverOptions solver;
  // Memory budget of the finished submaps (pipeline/submap_store.h).
  MemoryBudgetConfig memory;
  // False: the threads start in start(), so that tests can fill the queues first.
  bool start_threads = true;
};

// Throws covox::Error naming the first invalid parameter.
void validate(const SlamConfig& config);

// How many new submaps the backend lets enter a graph of `graph_submaps` submaps before it
// optimises again: max(optimize_every_n_submaps, floor(optimize_spacing_fraction x
// graph_submaps)); 0 when optimize_every_n_submaps is 0 (only on request and at the end).
int64_t submaps_between_optimizations(const SlamConfig& config, int64_t graph_submaps);

// One scan: points in the sensor frame and the sensor's odometry pose at the scan's stamp.
struct Scan {
  double stamp_s = 0.0;
  Eigen::Isometry3d T_odom_sensor = Eigen::Isometry3d::Identity();
  std::vector<Vec3f> points_sensor_m;
  std::vector<Rgb8> colors;  // empty, or one per point
  // Empty, or one per point: when it was measured, in seconds after stamp_s (a LiDAR driver's
  // per-point time field). With `sweep` known, the points are de-skewed to the stamp.
  std::vector<float> point_times_s;
  SweepOdometry sweep;
};

// One kind of external constraint (loop closures, absolute positions or heights).
struct ExternalConstraintCounters {
  int64_t received = 0;
  int64_t rejected_bad_input = 0;      // non-finite numbers, a non-rigid transform, bad information
  int64_t rejected_unknown_stamp = 0;  // no integrated scan within external_stamp_tolerance_s
  int64_t rejected_same_submap = 0;    // loop closures: both scans in one submap
  int64_t dropped_submap_lost = 0;     // accepted, but its submap never reached the graph
  int64_t added = 0;                   // entered the pose graph
  int64_t rejected_total() const {
    return rejected_bad_input + rejected_unknown_stamp + rejected_same_submap;
  }
};

struct SlamCounters {
  // Input side (add_scan and the sensor queue).
  int64_t scans_received = 0;              // every add_scan call
  int64_t scans_dropped_invalid_pose = 0;  // non-finite or non-rigid T_odom_sensor
  int64_t scans_dropped_empty_cloud = 0;
  int64_t scans_dropped_bad_stamp = 0;        // non-finite, or not after the previous scan's
  int64_t scans_dropped_bad_colors = 0;       // colour count not matching the point count
  int64_t scans_dropped_bad_point_times = 0;  // point_times_problem() (scan_deskew.h)
  int64_t scans_rejected_not_running = 0;     // after finish() or shutdown()
  int64_t scans_dropped_queue_full = 0;       // oldest scans dropped by the sensor queue
  int64_t scans_discarded_at_shutdown = 0;    // still queued when shutdown() ran
  int64_t scans_discarded_at_reset = 0;       // queued (or being integrated) when reset() ran
  // Frontend.
  int64_t scans_integrated = 0;
  int64_t scans_failed = 0;                  // the integrator threw (logged)
  int64_t points_integrated = 0;             // points handed to the integrator
  int64_t points_dropped_by_integrator = 0;  // non-finite, too close or too far
  // De-skewing: scans whose points were moved to their stamp; scans integrated as they are
  // because they carry no point times although the sensor moved more than a voxel at the
  // maximum ray length since the previous scan (a spinning LiDAR's clouds are then smeared);
  // scans with times but no odometry across their sweep.
  int64_t scans_deskewed = 0;
  int64_t scans_not_deskewed_no_times_moving = 0;
  int64_t scans_not_deskewed_no_sweep_odometry = 0;
  int64_t submaps_created = 0;
  int64_t submaps_dropped_queue_full = 0;  // oldest submaps dropped by the submap queue
  // Backend.
  int64_t submaps_finished = 0;
  int64_t submaps_failed = 0;  // finishing threw (logged)
  int64_t odometry_constraints = 0;
  int64_t optimizations = 0;
  int64_t optimizations_failed = 0;
  // Optimisations stopped by their solve budget (pose_graph.max_solves_per_new_submap).
  int64_t optimizations_over_budget = 0;
  // Registration constraints set aside by the consistency gate (registration.gate.max_residual_vox)
  // in the latest optimisation.
  int64_t registrations_set_aside = 0;
  // How far the latest solve moved the mapped submaps from their odometry: the RMS and the
  // largest distance between a submap's corrected and odometry positions (the world frame is the
  // odometry frame of the first submap).
  double correction_rms_m = 0.0;
  double correction_max_m = 0.0;
  // pose_graph.estimate_odometry_noise: the drift per metre the latest optimisation used (the
  // configured drift times the square root of the estimated variance factor); 0 when off.
  double odometry_drift_estimate_m_per_m = 0.0;
  double odometry_drift_estimate_deg_per_m = 0.0;
  // ... and the drift the revisits showed, the estimate's lower bound (revisit_drift_min_path_m):
  // from this many registrations; 0 when none or off.
  int64_t revisits_measuring_drift = 0;
  double revisit_drift_m_per_m = 0.0;
  double revisit_drift_deg_per_m = 0.0;
  RegistrationCounts registration;           // attempted, accepted and each reason for a rejection
  PlaceRecognitionCounts place_recognition;  // candidates, verified, accepted, rejections
  ExternalConstraintCounters loop_closures;
  ExternalConstraintCounters absolute_positions;
  ExternalConstraintCounters heights;
  int64_t resets = 0;                      // reset() and load_submaps() calls
  int64_t submaps_discarded_at_reset = 0;  // active, queued or being finished at a reset
  int64_t submaps_loaded = 0;              // by load_submaps()
  SubmapStoreCounters memory;              // where the finished submaps' voxels are

  // Every scan that was given but will never be integrated, for any counted reason.
  int64_t scans_dropped_total() const {
    return scans_dropped_invalid_pose + scans_dropped_empty_cloud + scans_dropped_bad_stamp +
           scans_dropped_bad_colors + scans_dropped_bad_point_times + scans_rejected_not_running +
           scans_dropped_queue_full + scans_discarded_at_shutdown + scans_discarded_at_reset +
           scans_failed;
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
  ModuleTiming registration;       // per submap: registration points and alignments
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
  std::vector<map::HostBlock> blocks;  // TSDF, colour and ESDF, as TsdfMap::snapshot() returns them
  // For load_submaps(), instead of `blocks`: the compact form (io/submap_codec.h) as a map file
  // stores it. A loaded submap that does not fit the device budget keeps these bytes (when their
  // distance scale is the system's) without encoding again.
  std::vector<uint8_t> encoded;
};

// A finished submap in the pose graph, as the outside sees it.
struct SubmapInfo {
  int64_t id = 0;
  Eigen::Isometry3d T_world_submap = Eigen::Isometry3d::Identity();  // corrected
  Eigen::Isometry3d T_odom_submap = Eigen::Isometry3d::Identity();   // from odometry
  SubmapStatistics statistics;
  Eigen::AlignedBox3d bounding_box_world;
  int64_t mesh_triangles = 0;
  bool loaded = false;  // from load_submaps(): its pose is fixed
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
  // After finish(): reopens the queues and starts the threads again. The finished submaps stay in
  // the graph as they are; the next scan starts a new submap, linked to the last one by odometry,
  // and its stamp must follow the last accepted one (unless reset() or load_submaps() ran).
  // Returns true when the system runs afterwards (also when it never stopped), false after
  // shutdown(), which is final.
  bool resume();
  bool running() const { return running_.load(); }
  // Entries waiting now: for diagnostics, and for offline runners that throttle their input
  // instead of letting the queues drop (a recorded flight should be processed completely).
  size_t sensor_queue_length() const { return sensor_queue_.size(); }
  size_t submap_queue_length() const { return submap_queue_.size(); }

  // Submaps in the pose graph with their corrected poses, in creation order.
  std::vector<SubmapInfo> submaps() const;
  // Every integrated scan's stamp with its corrected pose: T_W_S * T_odom_S^-1 * T_odom_sensor
  // of its submap, or, for a submap not (yet) in the graph, the correction of the latest earlier
  // submap that is (voxgraph's mission-to-odom correction). With
  // config.interpolate_trajectory_correction, blended towards the next graph submap's correction
  // (see SlamConfig).
  std::vector<StampedPose> corrected_trajectory() const;
  // The finished submaps' meshes moved to their corrected poses, as one mesh.
  map::Mesh combined_mesh() const;
  // The finished submaps (TSDF, colour, ESDF) at their corrected poses.
  std::vector<SubmapSnapshot> submap_snapshots();
  // Hands each finished submap, in graph order, to `write` in its compact form
  // (io/submap_codec.h, distance scale map_distance_scale_m()) at its corrected pose, one at a
  // time: what a map file stores (io::MapFileWriter), without the whole map in memory at once.
  // Waits for the backend's current step (src/pipeline/slam_system_store.cpp).
  using EncodedSubmapSink = std::function<void(int64_t id, const Eigen::Isometry3d& T_world_submap,
                                               const std::vector<uint8_t>& encoded)>;
  void write_submaps(const EncodedSubmapSink& write);
  // The compact form's distance scale: the TSDF truncation distance.
  float map_distance_scale_m() const { return config_.tsdf.truncation_distance_m; }
  SlamCounters counters() const;
  SlamTimings timings() const;
  // Each integrated scan's frontend time (seconds, the samples timings().tsdf sums) since the
  // previous call, oldest first: what a caller needs for latency percentiles over a window. At
  // most kScanDurationsKept wait between calls; older ones are dropped uncollected, so a caller
  // that never asks costs a fixed amount of memory.
  std::vector<double> take_scan_durations();
  static constexpr size_t kScanDurationsKept = 8192;
  // The latest optimisation's summary (default-constructed before the first).
  backend::PoseGraphSolverSummary last_solver_summary() const;
  // Every constraint in the pose graph (submap ids), for diagnostics and drawing the graph.
  std::vector<SubmapConstraint> constraints() const;

  // ---- External constraints and map management (thread-safe) ---------------------------------
  // A loop closure between the scans nearest to its stamps. Returns false (counted, logged) when
  // a stamp is not covered by any integrated scan, both scans lie in one submap, or the numbers
  // are bad (non-finite, non-rigid transform, information not symmetric PSD). Accepted ones
  // enter the graph, as a 4-DoF constraint between the two submaps (project_loop_closure()),
  // once both submaps are in it, and trigger an optimisation.
  bool add_loop_closure(const LoopClosure& closure);
  // GNSS: the sensor's position in the world at `stamp_s`, information over (x, y, z). Two or
  // more of them on different submaps (with horizontal information) pin the graph in the world
  // instead of the first submap.
  bool add_absolute_position(double stamp_s, const Eigen::Vector3d& position_world_m,
                             const Eigen::Matrix3d& information);
  // The sensor's height (world z) at `stamp_s`, information 1 / sigma^2.
  bool add_height(double stamp_s, double height_m, double information_z);
  // Optimise at the next backend iteration; after finish() or shutdown(), at once on the caller's
  // thread (constraints added since then are included).
  void request_optimization();
  // Discards every submap, scan and constraint; the threads keep running and the next scan starts
  // a new map (its stamps need not follow the old ones). Waits for the backend's current step.
  void reset();
  // Replaces the whole map by finished submaps (e.g. loaded from a map file): they enter the
  // graph as fixed-pose submaps with their stored poses; mapping continues in a new submap, whose
  // odometry frame is taken as the world frame until registration or a loop closure links it to
  // the loaded map. Throws covox::Error naming the submap when a pose is not a finite, gravity-
  // aligned rigid transform, ids repeat, or its blocks do not fit the map configuration; the map
  // is unchanged then. Under the memory budget the loaded submaps stay resident while they fit
  // beside the old map's resident ones; the rest enter the store compact, so a load never holds
  // more than the device budget plus one submap on the device.
  void load_submaps(std::vector<SubmapSnapshot> submaps);
  // The current correction T_W_odom (voxgraph's mission -> odom) of the latest mapped submap in
  // the graph; identity before the first.
  Eigen::Isometry3d T_world_odom() const;

  // ---- ROS-facing queries (src/pipeline/slam_system_queries.cpp) ----
  // What the ROS layer publishes, computed here so the nodelet stays thin. The two slices wait
  // for the backend's current step (they read finished submaps' voxels), so call them from a
  // thread that may wait (the nodelet's visualisation thread), never from the sensor callback.
  //
  // A finished submap's mesh in its own frame and its corrected pose T_W_S; false when no
  // submap in the graph has this id.
  bool submap_mesh(int64_t id, map::Mesh* mesh_submap, Eigen::Isometry3d* T_world_submap) const;
  // The ESDF of every finished submap at world height `height_m`, on a world-aligned grid of the
  // voxel size; where submaps overlap, a cell keeps the smallest distance (conservative for
  // planners). Points are reported at `height_m`.
  std::vector<integrators::SlicePoint> esdf_slice_world(double height_m);
  // The ESDF slice at world height `height_m` of the newest finished submap (the active submap
  // gets its ESDF only when it is finished), in world coordinates; `submap_id` receives its id,
  // -1 when there is none.
  std::vector<integrators::SlicePoint> esdf_slice_newest_submap(double height_m,
                                                                int64_t* submap_id);
  // The ESDF slice at world height `height_m` of the ACTIVE submap (still being integrated), at
  // its current corrected pose; `submap_id` receives its id, -1 when there is none yet. The
  // active submap has no ESDF while mapping, so this computes one without touching it: each call
  // asks the frontend for a host copy of the active submap's blocks (taken after its current
  // scan, or at once when it is idle; integration pauses only for the copy) and computes the
  // slice on the caller's thread from the latest copy, over the blocks within
  // esdf_max_distance_m of the slice height only. Never waits for the frontend: the result is
  // the copy requested by the previous call, so call it periodically; the first call returns
  // nothing. Exact (the same distances the finished submap will have) for the copied TSDF.
  std::vector<integrators::SlicePoint> esdf_slice_active_submap(double height_m,
                                                                int64_t* submap_id);
  // The ESDF of the finished submaps at points of the world (mission) frame, for planners: each
  // point is moved into every submap's frame at its corrected pose and sampled there
  // (integrators::query_esdf: trilinear over the 8 voxels around it); where several submaps
  // observe it, the smaller distance wins, as in esdf_slice_world(). The gradient is rotated
  // into the world frame. `valid` is 0 where no finished submap observes the 8 voxels around the
  // point (unknown space): distance and gradient mean nothing there.
  std::vector<integrators::EsdfSample> query_esdf_world(const std::vector<Vec3f>& points_world_m);
  // Every observed voxel of the finished submaps with a distance of at most max_distance_m, moved
  // into the world frame and merged on a world grid of the voxel size (a cell keeps the smallest
  // distance, as in esdf_slice_world()), reported at the cell centres. When more than
  // `max_points` cells remain, the ones with the smallest distances are kept (obstacles and the
  // space nearest to them) and `*truncated` is set.
  std::vector<integrators::SlicePoint> esdf_voxels_world(double max_distance_m, size_t max_points,
                                                         bool* truncated);

 private:
  // Calls `visit` with the voxels and the corrected pose of every finished submap, holding
  // backend_mutex_ so that none is removed meanwhile; a compacted submap is brought back for the
  // visit and is the first to leave again (the memory budget holds afterwards).
  void visit_finished_submaps(
      const std::function<void(const map::TsdfMap&, const Eigen::Isometry3d&)>& visit);
  struct TrajectoryEntry {
    double stamp_s;
    int64_t submap_id;
    Eigen::Isometry3d T_odom_sensor;
    Eigen::Isometry3d T_odom_submap;
  };
  // Queue entries carry the map generation they belong to: reset() bumps it, and whatever was
  // queued or in flight before is discarded when a thread meets it.
  struct QueuedScan {
    Scan scan;
    uint64_t generation = 0;
  };
  struct QueuedSubmap {
    std::unique_ptr<Submap> submap;
    uint64_t generation = 0;
  };
  // A submap in the graph (vertex order of pose_graph_).
  struct GraphSubmap {
    std::unique_ptr<Submap> submap;
    std::unique_ptr<SubmapRegistrationPoints> registration_points;  // null when disabled
    bool loaded = false;
    // Its wall map for the revisit start (pipeline/wall_map.h), built when first needed.
    std::unique_ptr<WallMapCache> walls = std::make_unique<WallMapCache>();
    // Its blocks on the host, for the overlap tests of every later submap (registration).
    std::unique_ptr<backend::SubmapFootprint> footprint;
  };

  RegistrationOdometry odometry_for_verification(const Submap& submap, double path_m) const;
  // The odometry constraint's information from the submap before it (sigmas and drift).
  Eigen::Matrix4d odometry_link_information(const SubmapStatistics& previous) const;
  // correction_rms_m / correction_max_m from the submaps' poses; caller holds state_mutex_.
  void update_correction_counters_locked();
  void frontend_loop();
  void backend_loop();
  void process_scan(const QueuedScan& queued);
  // Uploads the scan (points, colours, times) and integrates it into the active submap,
  // de-skewed when it can be (scan_deskew.h); counts the de-skewing outcome.
  integrators::IntegrationStats integrate_scan(const Scan& scan);
  void hand_over_active_submap();
  // Copies the active submap's blocks for esdf_slice_active_submap() (frontend thread only).
  void copy_active_submap_for_slice();
  // Finishes a submap and adds it to the graph; returns whether the every-n rule asks for an
  // optimisation.
  bool process_submap(QueuedSubmap item);
  // The remaining helpers need backend_mutex_.
  // A submap of load_submaps() built, finished and, past `room_bytes` of device memory (which it
  // lowers), released to its compact form `compact` (empty when it stays resident).
  GraphSubmap stage_loaded_submap(SubmapSnapshot& snapshot, MapIntegrators& integrators,
                                  double* room_bytes, std::vector<uint8_t>* compact);
  void add_to_pose_graph_locked(std::unique_ptr<Submap> submap,
                                std::unique_ptr<SubmapRegistrationPoints> points);
  // Every submap in the graph as a registration partner of the new `submap` (with kJoint, the
  // mapped ones in `joint_partners`), their odometry for verification; returns the new submap's.
  // Needs state_mutex_ as well.
  RegistrationOdometry list_partners_locked(const Submap& submap, bool joint,
                                            std::vector<RegistrationPartner>* partners,
                                            std::vector<RegistrationPartner>* joint_partners) const;
  // The positions (x, y in the submap's frame) of the scans integrated into `submap`, in order.
  std::vector<Eigen::Vector2d> submap_path_locked(const Submap& submap);
  // Place recognition's loop closures for a new submap (pipeline/place_recognition.h), appended
  // to `registrations`; `partners` and `joint_partners` are every earlier submap. The candidates'
  // maps are brought back within the memory budget before they are aligned.
  void propose_place_recognition_locked(const Submap& submap,
                                        const SubmapRegistrationPoints& points,
                                        const backend::Pose4Dof& guess,
                                        const std::vector<RegistrationPartner>& partners,
                                        const std::vector<RegistrationPartner>& joint_partners,
                                        const std::vector<int64_t>& joint_pair_partners,
                                        WallMapCache* walls, const RegistrationOdometry& odometry,
                                        std::vector<SubmapConstraint>* registrations,
                                        PlaceRecognitionCounts* counts);
  // Moves waiting external constraints whose submaps are in the graph into it; `final`: no more
  // submaps will come, so those still waiting are dropped (counted). Returns how many entered.
  int integrate_pending_constraints_locked(bool final);
  // One optimisation of the graph by optimizer_ (graph_optimizer.h), its outcome counted.
  void optimize_locked();
  class GraphAccess;  // the graph as optimizer_ sees it
  // kJoint: the dense registration terms of joint_pairs_ for `graph`; needs state_mutex_ (and
  // backend_mutex_ for the lifetime of the submaps they point to).
  std::vector<backend::RegistrationTerm> joint_terms_locked(
      const SubmapPoseGraph::BackendGraph& graph) const;
  void reset_locked();
  // Memory budget (src/pipeline/slam_system_store.cpp); all need backend_mutex_.
  // Brings back the voxels of the partners registration will read (chosen from the kept
  // footprints, so the choice itself needs no voxels), one at a time with the budget enforced
  // after each, the partners kept: the device holds at most the budget and one submap.
  void acquire_partners_locked(const std::vector<const RegistrationPartner*>& partners);
  // `mark_used` false: for sweeps over every submap (SubmapStore::acquire).
  bool acquire_locked(Submap& submap, bool mark_used = true);  // true: restored
  // Compacts and spills down to the budgets, least recently used first; `keep` (an id, or -1)
  // and the ids in `also_kept` stay (SubmapStore::enforce for `return_memory`).
  void enforce_budget_locked(int64_t keep, const std::unordered_set<int64_t>& also_kept = {},
                             bool return_memory = true);
  void join_threads();
  // The correction T_W_odom for scans of submap `submap_id`; needs state_mutex_.
  Eigen::Isometry3d correction_for_locked(int64_t submap_id) const;
  // The integrated scan nearest to `stamp_s` within the tolerance, or null; needs state_mutex_.
  const TrajectoryEntry* scan_near_locked(double stamp_s) const;
  ExternalConstraintCounters& external_counters_locked(SubmapConstraintKind kind);
  // Counts and logs (rate-limited) a refused external constraint; needs state_mutex_.
  void refuse_locked(int64_t* counter, const char* what, const std::string& why);

  const SlamConfig config_;
  BoundedQueue<QueuedScan> sensor_queue_;
  BoundedQueue<QueuedSubmap> submap_queue_;
  std::atomic<uint64_t> generation_{0};
  // Ids continue across resets, and after load_submaps() beyond the loaded ones.
  std::atomic<int64_t> next_submap_id_{0};

  // The graph's size at the latest optimisation (backend_mutex_): the spacing on long missions.
  size_t submaps_at_last_optimization_ = 0;
  // Frontend thread only. Its integration stage builds every active submap in turn.
  MapIntegrators frontend_integrators_;
  Buffer<Vec3f> points_buffer_;
  Buffer<Rgb8> colors_buffer_;
  Buffer<float> times_buffer_;
  // The previous integrated scan's stamp and pose, for the warning about clouds without point
  // times from a moving sensor.
  double previous_scan_stamp_s_ = -std::numeric_limits<double>::infinity();
  Eigen::Isometry3d previous_T_odom_sensor_ = Eigen::Isometry3d::Identity();
  std::unique_ptr<Submap> active_submap_;
  uint64_t active_generation_ = 0;
  Eigen::Vector3d last_position_odom_m_ = Eigen::Vector3d::Zero();

  // The active submap's blocks as last copied for esdf_slice_active_submap(); the copy is
  // requested by the caller and taken by the frontend between scans.
  struct ActiveSubmapCopy {
    int64_t id = -1;
    uint64_t generation = 0;
    Eigen::Isometry3d T_odom_submap = Eigen::Isometry3d::Identity();
    std::vector<map::HostBlock> blocks;
  };
  std::atomic<bool> active_copy_requested_{false};
  std::mutex active_copy_mutex_;
  std::shared_ptr<const ActiveSubmapCopy> active_copy_;

  // Finished submaps' voxels under the memory budget, and what brings them back (all used
  // under backend_mutex_).
  std::unique_ptr<SubmapStore> store_;
  integrators::EsdfIntegrator restore_esdf_;
  Stream restore_stream_;

  // Backend thread only (and finish() after the threads have joined). Its integration stage
  // finishes every submap; its stream also runs the registrations.
  MapIntegrators backend_integrators_;
  GraphOptimizer optimizer_;

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
  std::atomic<bool> optimization_requested_{false};
  bool started_ = false;
  bool stopped_ = false;

  // Held for every change of the graph's structure (the backend's steps, optimisations, reset,
  // load_submaps, finish's final solve), so the backend can read submaps' voxels without
  // state_mutex_ while nobody replaces them. Lock order: backend_mutex_, then state_mutex_.
  std::mutex backend_mutex_;

  // Shared state read by the accessors.
  mutable std::mutex state_mutex_;
  SlamCounters counters_;
  SlamTimings timings_;
  std::vector<GraphSubmap> graph_submaps_;  // node k of pose_graph_ is graph_submaps_[k]
  SubmapPoseGraph pose_graph_;
  std::vector<SubmapConstraint> pending_constraints_;  // external, waiting for their submaps
  // kJoint: overlapping pairs solved as dense terms (ids of the points' and the field's submap).
  struct JointPair {
    int64_t points_submap;
    int64_t field_submap;
  };
  std::vector<JointPair> joint_pairs_;
  PlaceRecognizer place_recognizer_;  // the finished submaps' descriptors (backend_mutex_)
  backend::PoseGraphSolverSummary last_summary_;
  std::vector<TrajectoryEntry> trajectory_;
  std::deque<double> scan_durations_s_;  // take_scan_durations()'s, at most kScanDurationsKept
};

}  // namespace pipeline
}  // namespace covox

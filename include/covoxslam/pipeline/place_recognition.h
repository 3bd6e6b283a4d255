#pragma once
// Place recognition over finished submaps: loop closures that do not depend on the current pose
// estimate. Registration (registration_constraints.h) aligns a new submap only to the submaps its
// current corrected pose makes it overlap, so once the odometry has drifted further than that a
// revisit goes unnoticed. Here every finished submap gets descriptors of its geometry alone
// (PlaceDescriptor), and the earlier submaps whose descriptors resemble the new one's are aligned
// to it from the relative pose the descriptors suggest, verified and confirmed (PlaceRecognizer).
// docs/design.md ("Registration", place recognition) says why confirmed closures bypass the
// consistency gate.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "covoxslam/backend/pose_graph_types.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/tsdf_map.h"
#include "covoxslam/pipeline/registration_constraints.h"
#include "covoxslam/pipeline/submap_pose_graph.h"

namespace covox {
namespace pipeline {

// Section `place_recognition` of the configuration files (docs/parameters.md).
struct PlaceRecognitionConfig {
  bool enabled = true;
  int rings = 20;
  int sectors = 60;
  double max_radius_m = 20.0;
  // Earlier submaps scored by the full descriptor per new submap (nearest ring keys).
  int candidates = 5;
  // Ring keys and polar descriptors are taken about points this far apart along each submap's
  // path (its scans' positions, from the first), so that a revisit whose submaps start elsewhere
  // on the same path is compared about nearby points; 0: about the submap's origin only.
  double anchor_spacing_m = 2.5;
  // The submaps with the last this many ids before the new one are never candidates.
  int exclude_recent_submaps = 6;
  // Full-descriptor distance in [0, 1] above which a candidate is dropped.
  double max_descriptor_distance = 0.5;
  // The bird's-eye correlation covers offsets within this of the origins' coincidence (x and y).
  double translation_search_m = 12.0;
  // Least bird's-eye overlap score in [0, 1] for a candidate to be aligned.
  double min_overlap_score = 0.3;
  // The verifying alignment's residual RMS limit in voxels (registration.acceptance's
  // max_residual_rms_vox, applied here even where the registration's own is off or looser).
  double max_residual_rms_vox = 0.8;
  // Closures are checked against the odometry as registration.verification checks alignments
  // (odometry_mahalanobis_sq), with at least this drift per metre of path between the two
  // submaps where the pose graph's own odometry drift is smaller or 0: the most the odometry can
  // plausibly drift, so that a revisit far from its estimate passes and an alike place whose
  // offset the odometry cannot explain does not.
  double odometry_drift_m_per_m = 0.02;
  double odometry_drift_deg_per_m = 0.1;
  // The check's threshold on the squared Mahalanobis distance (x, y, z, yaw), applied where
  // registration.verification's is off or looser; 0: closures are not checked.
  double max_odometry_mahalanobis_sq = 16.0;
  // A verified closure enters the pose graph only once a second one, from another new submap
  // within confirm_window_submaps of its own and to an earlier submap within as many of its
  // earlier one, agrees with it: the cycle of the two closures and
  // the odometry between their ends closes to within confirm_tolerance_m and _deg plus the
  // closures' drift per metre over those two stretches of odometry. A lone closure or one that
  // disagrees with every other is dropped once the window has passed. Confirmed closures are
  // judged by this test, not by the registration's consistency gate: a revisit after a long
  // path moves the graph further than the gate allows any one constraint to disagree with it.
  int confirm_window_submaps = 10;
  double confirm_tolerance_m = 1.0;
  double confirm_tolerance_deg = 3.0;
};

// Throws covox::Error naming the first invalid parameter (prefix "place_recognition.").
void validate(const PlaceRecognitionConfig& config);

// A map column holding surface voxels: its centre in the map frame and the z of its lowest and
// highest surface voxel centres.
struct SurfaceColumn {
  double x_m = 0.0, y_m = 0.0;
  double bottom_m = 0.0, top_m = 0.0;
};

// Every surface column of `map` (|distance| < surface_band_m, weight > 0), in (x, y) order. Runs
// on the map's device.
std::vector<SurfaceColumn> surface_columns(const map::TsdfMap& map, double surface_band_m,
                                           const Stream& stream);

// Descriptor (Scan-Context-like). The submap's surface columns (voxel columns (x, y) holding a
// TSDF surface voxel: weight > 0 and |distance| under the surface band) in the submap frame S,
// which is gravity aligned, binned on a polar grid of `rings` x `sectors` around a centre out to
// max_radius_m. A cell holds the vertical extent of its surfaces (highest top minus lowest
// bottom, metres) when it is at least half a metre, else 0: ground alone, which every submap has
// around its path, would make any two submaps alike. The extent does not depend on the height
// of the path or on the odometry's drift in z. The ring key (each ring's mean over its sectors)
// does not change when the submap turns about z, so it is what the index searches. Descriptors
// are taken about several anchors along the submap's path (path_anchors): two passes over a place
// cut their submaps at different points, but some pair of anchors lies within half the spacing.
// The grids keep S's axes, so a sector shift between two anchors' descriptors is the submaps'
// relative yaw. The columns about the origin on a Cartesian grid of the ring width (the
// bird's-eye image) give the translation and the yaw.
struct PlaceDescriptor {
  int rings = 0;
  int sectors = 0;
  double max_radius_m = 0.0;
  // rings x sectors, ring-major; the vertical extent of the cell's surfaces (m), 0 when empty.
  std::vector<float> polar;
  std::vector<float> ring_key;  // per ring: the mean of its sectors
  // Bird's-eye image: (2 rings) x (2 rings) cells of max_radius_m / rings around the origin,
  // row-major from (-max_radius_m, -max_radius_m); the extent of the cell's surfaces, 0 empty.
  std::vector<float> bird_eye;
  int64_t columns = 0;  // surface columns within max_radius_m
  bool empty() const { return columns == 0; }
};

// The descriptor of the given columns (the surface band is a voxel), about `centre_m` (x, y in
// the columns' frame; the grids keep that frame's axes).
PlaceDescriptor place_descriptor(const std::vector<SurfaceColumn>& columns,
                                 const PlaceRecognitionConfig& config,
                                 const Eigen::Vector2d& centre_m = Eigen::Vector2d::Zero());
// The points of a submap's path (x, y in its frame, in scan order) that descriptors are taken
// about: the first, then each point at least `spacing_m` of path after the previous one, at most
// kMaxPathAnchors (evenly thinned); only the origin when the path is empty or spacing_m is 0.
constexpr int kMaxPathAnchors = 16;
std::vector<Eigen::Vector2d> path_anchors(const std::vector<Eigen::Vector2d>& path_m,
                                          double spacing_m);
// The descriptor of a finished submap's map (its columns on the map's device, binned on the host).
PlaceDescriptor place_descriptor(const map::TsdfMap& map, const PlaceRecognitionConfig& config,
                                 const Stream& stream);

struct DescriptorMatch {
  double distance = 1.0;  // in [0, 1]; 1 when neither has structure
  int shift = 0;          // sector s of `moving` matches sector s + shift of `fixed`
  double yaw_rad = 0.0;   // the yaw of T_fixed_moving that the shift means, in (-pi, pi]
};
// The distance at the best sector shift: 1 minus the mean cosine similarity of the sector
// columns over the sectors where either has structure (one side empty: similarity 0); the shift
// is a first guess of the relative yaw.
//
// Both descriptors must have the same grid.
DescriptorMatch match_descriptors(const PlaceDescriptor& moving, const PlaceDescriptor& fixed);

struct BirdEyeMatch {
  backend::Pose4Dof T_fixed_moving;  // x, y and yaw; z 0
  double score = 0.0;                // in [0, 1]
};
// The images are correlated around the origins' coincidence at every sector's yaw, starting from
// the descriptors' shift (which wins ties); the score is the overlap of the two extents,
// sum min(a, b) over the matched cells divided by the smaller of the two totals (at most 1).
//
// The best overlap of the two bird's-eye images over offsets within +-translation_search_m and
// every sector's yaw from `yaw_rad` on, refined to half a sector.
BirdEyeMatch match_bird_eye(const PlaceDescriptor& moving, const PlaceDescriptor& fixed,
                            double yaw_rad, const PlaceRecognitionConfig& config);

// Ring keys of earlier submaps, searched for the nearest ones (Euclidean). A k-d tree over all
// but the latest insertions, which are searched one by one and merged into the tree once there
// are kMaxUnindexed of them: a query costs about the tree's depth plus kMaxUnindexed.
class RingKeyIndex {
 public:
  static constexpr size_t kMaxUnindexed = 32;
  void clear();
  void add(int64_t id, const std::vector<float>& key);
  size_t size() const { return keys_.size(); }
  // The ids of at most `k` nearest keys among those with id <= max_id, nearest first (ties: the
  // lower id first).
  std::vector<int64_t> nearest(const std::vector<float>& key, size_t k, int64_t max_id) const;

 private:
  struct Node {
    int32_t item = -1;
    int32_t dimension = 0;
    int32_t left = -1, right = -1;
  };
  struct Search;
  int32_t build(std::vector<int32_t>& items, size_t begin, size_t end, int depth);
  void search(int32_t node, Search* state) const;

  std::vector<int64_t> ids_;
  std::vector<std::vector<float>> keys_;
  std::vector<Node> nodes_;
  int32_t root_ = -1;
  size_t indexed_ = 0;  // items [0, indexed_) are in the tree
};

// A closure the registration accepted, with both submaps' odometry (for the confirmation).
struct VerifiedClosure {
  SubmapConstraint constraint;
  RegistrationOdometry earlier_odometry, new_odometry;
};

// How far two verified closures disagree (PlaceRecognitionConfig::confirm_*): the larger of the
// cycle's translation and yaw errors over their tolerances, squared; <= 1 when they agree.
double closure_disagreement(const VerifiedClosure& a, const VerifiedClosure& b,
                            const PlaceRecognitionConfig& config);

// What place recognition did; the verification's own rejections are in `registration`.
struct PlaceRecognitionCounts {
  int64_t queries = 0;              // submaps searched for
  int64_t candidates = 0;           // earlier submaps scored by the full descriptor
  int64_t skipped_linked = 0;       // already constrained to the new submap by registration
  int64_t rejected_descriptor = 0;  // distance above max_descriptor_distance
  int64_t rejected_overlap = 0;     // bird's-eye score below min_overlap_score
  int64_t verified = 0;             // aligned by the registration (registration.attempted)
  int64_t unconfirmed = 0;  // accepted by the registration, no other closure agreed in the window
  int64_t accepted = 0;     // constraints added (confirmed)
  RegistrationCounts registration;  // the alignments' counts (their rejections by reason)
  int64_t rejected_total() const {
    return rejected_descriptor + rejected_overlap + (verified - registration.accepted) +
           unconfirmed;
  }
  void add(const PlaceRecognitionCounts& other);
};

// An earlier submap whose descriptor resembles the new one's, with the relative pose the two
// descriptors suggest.
struct PlaceCandidate {
  int64_t id = -1;
  backend::Pose4Dof T_fixed_moving;  // earlier <- new: x, y and yaw of the bird's-eye match; z 0
  double descriptor_distance = 1.0;
  double overlap_score = 0.0;
};

// Search: each anchor's ring key is looked up among the earlier anchors' keys (the submaps of the
// last exclude_recent_submaps ids left out: they overlap the new one anyway and the odometry
// links them); the earlier submaps with the nearest keys, each at its best pair of anchors, are
// scored by match_descriptors and match_bird_eye. Verification: a candidate that passes
// max_descriptor_distance and min_overlap_score is aligned by the registration's own aligner from
// the matched relative pose (registration_constraint_from_guess, with its wall search and every
// acceptance test, the residual test at least as strict as max_residual_rms_vox), and checked
// against the odometry with at least the closures' drift per metre of path between the two
// submaps; each rejection is counted by reason. Confirmation: a submap of a different place with
// the same kind of structure (two alike buildings) can pass all that, so a verified closure waits
// until a closure of another new submap agrees with it (closure_disagreement); then both enter
// the graph as registration constraints marked from_place_recognition.
//
// The descriptors of the finished submaps and their index.
class PlaceRecognizer {
 public:
  explicit PlaceRecognizer(const PlaceRecognitionConfig& config);
  const PlaceRecognitionConfig& config() const { return config_; }
  void clear();
  size_t size() const { return descriptors_.size(); }

  // The search: the earlier submaps among `earlier_ids` (those without a descriptor here are not
  // candidates) whose descriptors pass max_descriptor_distance and min_overlap_score against the
  // new finished submap `id`, with their matched relative poses; `linked`: ids already
  // constrained to it, skipped. Adds the new submap's descriptor. Reads no earlier map, so the
  // candidates' maps can be brought back (memory budget) before verify(). Nothing when disabled.
  // `path_m`: the submap's scan positions in its frame (may be empty: the origin alone).
  std::vector<PlaceCandidate> search(int64_t id, const map::TsdfMap& map,
                                     const std::vector<Eigen::Vector2d>& path_m,
                                     const std::vector<int64_t>& earlier_ids,
                                     const std::vector<int64_t>& linked, const Stream& stream,
                                     PlaceRecognitionCounts* counts);
  // The verification: each candidate aligned by the registration from its matched pose and
  // judged by the closures' tests; those accepted (constraints of kind kRegistration from the
  // earlier submap to `id`). `earlier` holds each candidate's map, resident.
  std::vector<VerifiedClosure> verify(
      int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
      const backend::Pose4Dof& pose, const std::vector<PlaceCandidate>& candidates,
      const std::vector<RegistrationPartner>& earlier, const SubmapRegistrationConfig& registration,
      const Stream& stream, WallMapCache* own_walls, const RegistrationOdometry& odometry,
      PlaceRecognitionCounts* counts) const;
  // The confirmation: the closures of new submap `id` (verify()) joined to those waiting; the
  // loop-closure constraints confirmed now. Drops the closures waiting since before
  // id - confirm_window_submaps.
  std::vector<SubmapConstraint> confirm(int64_t id, const std::vector<VerifiedClosure>& verified,
                                        PlaceRecognitionCounts* counts);
  // The verified closures kept for confirmation (those of the last confirm_window_submaps).
  size_t waiting() const { return waiting_.size(); }
  // search(), verify() and confirm(), for callers whose earlier maps are all resident.
  std::vector<SubmapConstraint> propose(
      int64_t id, const map::TsdfMap& map, const SubmapRegistrationPoints& points,
      const backend::Pose4Dof& pose, const std::vector<RegistrationPartner>& earlier,
      const std::vector<int64_t>& linked, const SubmapRegistrationConfig& registration,
      const Stream& stream, WallMapCache* own_walls, const RegistrationOdometry& odometry,
      PlaceRecognitionCounts* counts);

 private:
  // Per submap: the descriptor about its origin (whose bird's-eye image the candidates are
  // matched with) and the polar descriptors about its path anchors (bird's-eye images dropped),
  // whose ring keys are in the index as id * kMaxPathAnchors + anchor.
  struct Entry {
    int64_t id;
    PlaceDescriptor descriptor;
    std::vector<PlaceDescriptor> anchors;
  };
  // The earlier submaps nearest to the new entry's anchors by ring key (each at its best pair of
  // anchors), nearest first, at most config.candidates of them: (submap id, own, their anchor).
  struct AnchorPair {
    int64_t id;
    size_t own, their;
  };
  std::vector<AnchorPair> nearest_submaps(const Entry& entry, int64_t max_id) const;
  const Entry* find(int64_t id) const;
  // The registration's tests as closures need them (see PlaceRecognitionConfig).
  SubmapRegistrationConfig closure_checks(const SubmapRegistrationConfig& registration) const;
  // The odometry with at least the closures' drift per metre.
  RegistrationOdometry with_closure_drift(RegistrationOdometry odometry) const;
  RegistrationPartner with_closure_drift(RegistrationPartner partner) const;

  PlaceRecognitionConfig config_;
  std::vector<Entry> descriptors_;  // in id order
  struct Waiting {
    VerifiedClosure closure;
    bool confirmed = false;  // already in the graph: a witness for later closures
  };
  std::vector<Waiting> waiting_;  // closures of the last confirm_window_submaps new submaps
  RingKeyIndex index_;
};

}  // namespace pipeline
}  // namespace covox

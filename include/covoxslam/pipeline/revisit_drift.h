#pragma once
// How far the odometry drifts per metre of path, as the revisits in the pose graph show it.
//
// The odometry's per-link noise (variance components, estimate_variance_ratios) describes the
// error of one link as if the links' errors were independent. Real odometry drift is not: a scale
// or yaw-rate bias adds the same error to every link, so a chain of n links ends n (not sqrt(n))
// link errors off. Only a revisit (a registration between two submaps far apart along the path)
// measures the chain's error directly: its measurement against the odometry's own relative pose
// of the two submaps. The rate below is that disagreement per metre of path between them, which
// is the drift a white per-link model would need per metre to explain the revisit.
#include <cstdint>
#include <vector>

#include "covoxslam/pipeline/submap_pose_graph.h"

namespace covox {
namespace pipeline {

struct RevisitDrift {
  double m_per_m = 0.0;    // translation (norm of x, y, z) per metre of path
  double rad_per_m = 0.0;  // yaw per metre of path
  int revisits = 0;        // the registrations the rates come from
};

// The least-squares slope through the origin of the revisits' disagreements with the odometry
// against their path: sqrt(sum e^2 / sum L^2) over every active registration constraint whose
// submaps lie at least min_path_m apart along the path (L; shorter spans measure the
// registration's error more than the odometry's). e: the measurement's translation (yaw) against
// the relative pose of the odometry constraints composed from `from` to `to`. path_at_node_m[k]
// is the path from the first submap to the start of graph.nodes()[k]. A pair without an unbroken
// odometry chain between them is skipped; no revisit: zeros.
RevisitDrift estimate_revisit_drift(const SubmapPoseGraph& graph,
                                    const std::vector<double>& path_at_node_m, double min_path_m);

}  // namespace pipeline
}  // namespace covox

#pragma once
// Top-view wall maps of submaps and a correlative search between two of them: the start of a
// revisit's registration, which may begin metres off, outside the distance-field aligner's basin.
// That aligner sees walls only through registration points whose eight trilinear corners are
// observed in the partner, which walls (unobserved behind, holed between sparse LiDAR rays)
// rarely give. A top view needs no observed neighbourhood: a column holds a wall when one of its
// surface voxels has a TSDF gradient within about 25 degrees of horizontal. Two submaps' wall
// columns are matched over a grid of offsets and yaws by the columns landing on a wall of the
// other (a Gaussian of the distance), so the result does not depend on a basin. The search runs
// on the caller's device and is deterministic: the best score wins, ties go to the first pose.
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Core>

#include "covoxslam/backend/pose_graph_types.h"
#include "covoxslam/core/stream.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace pipeline {

// A submap's wall columns (centres in the submap frame, x and y) and the distance from any column
// of its bounding box (plus a margin) to the nearest wall column, capped.
class WallMap {
 public:
  WallMap() = default;
  // Wall columns of `map` on a grid of cell_m (the map's voxel size), distances capped at cap_m.
  static WallMap from_map(const map::TsdfMap& map, double cap_m, const Stream& stream);
  // From given wall column centres (tests); same grid and cap rules.
  static WallMap from_columns(const std::vector<Eigen::Vector2d>& columns_m, double cell_m,
                              double cap_m);

  const std::vector<Eigen::Vector2d>& columns() const { return columns_; }
  double cell_m() const { return cell_m_; }
  // Distance (m) from (x, y) to the nearest wall column, cap_m where none is nearer or outside.
  double distance_m(double x, double y) const;

  // A value of every distance cell and of every point outside the grid, in the grid's layout:
  // what a search looks up instead of evaluating a function of distance_m at every look-up.
  struct CellTable {
    std::vector<double> inside;  // row-major, size_x columns, size_y rows
    double outside = 0.0;
    int32_t origin_x = 0, origin_y = 0, size_x = 0, size_y = 0;
  };
  // `value` of each cell's distance (as distance_m returns it) and of the cap.
  template <typename Value>
  CellTable cell_table(Value value) const {
    CellTable table;
    table.inside.reserve(distance_.size());
    for (const float d : distance_) table.inside.push_back(value(static_cast<double>(d)));
    table.outside = value(cap_m_);
    table.origin_x = origin_x_;
    table.origin_y = origin_y_;
    table.size_x = size_x_;
    table.size_y = size_y_;
    return table;
  }

 private:
  std::vector<Eigen::Vector2d> columns_;
  double cell_m_ = 0.2;
  double cap_m_ = 1.0;
  int32_t origin_x_ = 0, origin_y_ = 0, size_x_ = 0, size_y_ = 0;
  std::vector<float> distance_;
};

// A finished submap's wall map, built at most once while its voxels stay (at the first revisit
// that needs it) and shared by every later registration with that submap: building one extracts
// and evaluates every surface voxel of the submap, and a submap is the partner of several
// revisits. When the memory budget compacts the submap its wall map is released with its voxels
// (release()), so that what a finished submap keeps in memory stays small, and the next get()
// builds it again from the voxels brought back.
class WallMapCache {
 public:
  // Distances capped at this (m): beyond three Gaussian sigmas of the search a column scores 0.
  static constexpr double kCapM = 1.0;
  // The wall map of `map` (the same map at every call since the last release()).
  const WallMap& get(const map::TsdfMap& map, const Stream& stream);
  // Frees the wall map; a reference get() returned before is invalid afterwards.
  void release();
  // Whether a wall map is held.
  bool holds_walls();

 private:
  std::mutex mutex_;
  std::unique_ptr<WallMap> walls_;
};

struct WallSearchConfig {
  double range_m = 2.5;  // offsets within +-range_m in x and y around the guess
  double step_m = 0.1;
  double yaw_range_rad = 0.0523598775598299;  // +-3 degrees
  double yaw_step_rad = 0.00872664625997165;  // 0.5 degrees
  double sigma_m = 0.15;       // a column scores exp(-d^2 / (2 sigma^2)) at distance d
  int64_t max_columns = 1500;  // of the moving map (an even subsample beyond)
};

struct WallMatch {
  backend::Pose4Dof T_fixed_moving;  // x, y, yaw searched; z as the guess
  double score = 0.0;                // sum over the moving columns (matched columns, about)
};

// The pose of `moving` in `fixed`'s frame with the best score on the grid around `guess`; the
// grid's scores are summed on `stream`'s device (the same sums on either backend).
WallMatch match_walls(const WallMap& moving, const WallMap& fixed, const backend::Pose4Dof& guess,
                      const WallSearchConfig& config, const Stream& stream = Stream());

}  // namespace pipeline
}  // namespace covox

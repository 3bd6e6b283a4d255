#include "covoxslam/pipeline/wall_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <utility>

#include "covoxslam/backend/registration.h"
#include "covoxslam/core/error.h"

namespace covox {
namespace pipeline {

namespace {

// A surface voxel's distance gradient within about 25 degrees of horizontal (cos 25 = 0.906).
constexpr double kWallHorizontalFraction = 0.9;

int32_t cell_of(double coordinate_m, double cell_m) {
  return static_cast<int32_t>(std::floor(coordinate_m / cell_m));
}

}  // namespace

WallMap WallMap::from_columns(const std::vector<Eigen::Vector2d>& columns_m, double cell_m,
                              double cap_m) {
  if (!(cell_m > 0.0) || !(cap_m > 0.0) || !std::isfinite(cell_m) || !std::isfinite(cap_m)) {
    throw Error("wall map: cell_m and cap_m must be finite and > 0");
  }
  WallMap wall;
  wall.cell_m_ = cell_m;
  wall.cap_m_ = cap_m;
  std::set<std::pair<int32_t, int32_t>> cells;
  for (const Eigen::Vector2d& c : columns_m) {
    if (c.allFinite()) cells.emplace(cell_of(c.x(), cell_m), cell_of(c.y(), cell_m));
  }
  if (cells.empty()) return wall;
  int32_t min_x = std::numeric_limits<int32_t>::max(), min_y = min_x;
  int32_t max_x = std::numeric_limits<int32_t>::min(), max_y = max_x;
  for (const auto& [x, y] : cells) {
    wall.columns_.emplace_back((x + 0.5) * cell_m, (y + 0.5) * cell_m);
    min_x = std::min(min_x, x);
    max_x = std::max(max_x, x);
    min_y = std::min(min_y, y);
    max_y = std::max(max_y, y);
  }
  // Distances by stamping a disc of radius cap around every wall cell (cap is a few cells).
  const int32_t r = static_cast<int32_t>(std::ceil(cap_m / cell_m));
  wall.origin_x_ = min_x - r;
  wall.origin_y_ = min_y - r;
  wall.size_x_ = max_x - min_x + 1 + 2 * r;
  wall.size_y_ = max_y - min_y + 1 + 2 * r;
  wall.distance_.assign(static_cast<size_t>(wall.size_x_) * wall.size_y_,
                        static_cast<float>(cap_m));
  for (const auto& [x, y] : cells) {
    for (int32_t dy = -r; dy <= r; ++dy) {
      for (int32_t dx = -r; dx <= r; ++dx) {
        const double d = cell_m * std::hypot(dx, dy);
        if (d > cap_m) continue;
        const size_t index =
            static_cast<size_t>(y - wall.origin_y_ + dy) * wall.size_x_ + (x - wall.origin_x_ + dx);
        wall.distance_[index] = std::min(wall.distance_[index], static_cast<float>(d));
      }
    }
  }
  return wall;
}

WallMap WallMap::from_map(const map::TsdfMap& map, double cap_m, const Stream& stream) {
  // Every surface voxel, and its gradient in its own map: the registration residual of the map
  // against itself at the identity carries d(distance)/d(x, y, z) in its Jacobian.
  backend::RegistrationPointsConfig all;
  all.sampling_ratio = 1.0f;
  const backend::RegistrationPoints points = backend::extract_registration_points(map, all, stream);
  const std::vector<backend::RegistrationPoint> host = points.points.to_host(stream);
  // The TSDF's own gradient: a band of 2.5 voxels keeps a surface voxel's neighbours on the TSDF
  // (the ESDF beyond is unsigned and bends the gradient) while staying under the usual truncation
  // of 3 voxels, beyond which TSDF values are clamped. Under the aligner's narrower band the
  // neighbours of many wall voxels fall on the ESDF and bend their gradients, and fewer columns
  // land on the walls (test/pipeline_wall_map_test.cpp checks the share that does). Floor seen
  // at grazing angles is what remains.
  backend::RegistrationResidualConfig gradient_config;
  gradient_config.tsdf_band_m = 2.5f * map.voxel_size_m();
  Buffer<backend::RegistrationResidual> residuals(map.device());
  backend::evaluate_registration_residuals(points, map, backend::Pose4Dof(), backend::Pose4Dof(),
                                           gradient_config, &residuals, stream);
  const std::vector<backend::RegistrationResidual> at_home = residuals.to_host(stream);
  std::vector<Eigen::Vector2d> columns;
  for (size_t k = 0; k < host.size(); ++k) {
    const backend::RegistrationResidual& r = at_home[k];
    const double horizontal = std::hypot(r.jacobian_i[0], r.jacobian_i[1]);
    if (!r.valid ||
        !(horizontal > kWallHorizontalFraction * std::hypot(horizontal, r.jacobian_i[2])))
      continue;
    columns.emplace_back(host[k].position_m.x, host[k].position_m.y);
  }
  return from_columns(columns, map.voxel_size_m(), cap_m);
}

const WallMap& WallMapCache::get(const map::TsdfMap& map, const Stream& stream) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!walls_) walls_ = std::make_unique<WallMap>(WallMap::from_map(map, kCapM, stream));
  return *walls_;
}

double WallMap::distance_m(double x, double y) const {
  const int64_t ix = static_cast<int64_t>(std::floor(x / cell_m_)) - origin_x_;
  const int64_t iy = static_cast<int64_t>(std::floor(y / cell_m_)) - origin_y_;
  if (ix < 0 || iy < 0 || ix >= size_x_ || iy >= size_y_) return cap_m_;
  return distance_[static_cast<size_t>(iy) * size_x_ + static_cast<size_t>(ix)];
}

namespace {

// Per grid offset along one axis, the table cell a moved coordinate falls in (as distance_m
// computes it), -1 outside the table.
void cells_along_axis(double coordinate_m, const std::vector<double>& offsets_m, double cell_m,
                      int32_t origin, int32_t size, std::vector<int64_t>* cells) {
  for (size_t k = 0; k < offsets_m.size(); ++k) {
    const int64_t cell =
        static_cast<int64_t>(std::floor((coordinate_m + offsets_m[k]) / cell_m)) - origin;
    (*cells)[k] = cell >= 0 && cell < size ? cell : -1;
  }
}

// Adds one moved column's score at every grid offset: offset (cx, cy) reads the table at
// (xs[cx], ys[cy]). Scores accumulate column by column in the columns' order, so every offset's
// sum is the same sequence of additions as evaluating that offset on its own.
void add_column_scores(const WallMap::CellTable& table, const std::vector<int64_t>& xs,
                       const std::vector<int64_t>& ys, std::vector<double>* scores) {
  const size_t side = xs.size();
  for (size_t cy = 0; cy < side; ++cy) {
    double* row_scores = scores->data() + cy * side;
    if (ys[cy] < 0) {
      for (size_t cx = 0; cx < side; ++cx) row_scores[cx] += table.outside;
      continue;
    }
    const double* row = table.inside.data() + static_cast<size_t>(ys[cy]) * table.size_x;
    for (size_t cx = 0; cx < side; ++cx)
      row_scores[cx] += xs[cx] >= 0 ? row[xs[cx]] : table.outside;
  }
}

}  // namespace

WallMatch match_walls(const WallMap& moving, const WallMap& fixed, const backend::Pose4Dof& guess,
                      const WallSearchConfig& config) {
  if (!(config.range_m >= 0.0) || !(config.step_m > 0.0) || !(config.yaw_range_rad >= 0.0) ||
      !(config.yaw_step_rad > 0.0) || !(config.sigma_m > 0.0) || config.max_columns < 1) {
    throw Error("wall search: ranges must be >= 0, steps, sigma and max_columns > 0");
  }
  const std::vector<Eigen::Vector2d>& all = moving.columns();
  std::vector<Eigen::Vector2d> columns;
  const size_t stride =
      std::max<size_t>(1, (all.size() + config.max_columns - 1) / config.max_columns);
  for (size_t k = 0; k < all.size(); k += stride) columns.push_back(all[k]);
  const int32_t n = static_cast<int32_t>(std::floor(config.range_m / config.step_m + 1e-9));
  const int32_t m =
      static_cast<int32_t>(std::floor(config.yaw_range_rad / config.yaw_step_rad + 1e-9));
  const int32_t yaws = 2 * m + 1, side = 2 * n + 1;
  const double inverse_two_sigma2 = 1.0 / (2.0 * config.sigma_m * config.sigma_m);
  const double cutoff_m = 3.0 * config.sigma_m;
  // A column scores exp(-d^2 / (2 sigma^2)) at distance d from the nearest wall, 0 from the
  // cutoff on: evaluated once per cell of the fixed map instead of once per look-up.
  const WallMap::CellTable table = fixed.cell_table(
      [&](double d) { return d < cutoff_m ? std::exp(-d * d * inverse_two_sigma2) : 0.0; });
  std::vector<double> offsets_x(side), offsets_y(side);
  for (int32_t k = 0; k < side; ++k) {
    offsets_x[k] = guess.x + (k - n) * config.step_m;
    offsets_y[k] = guess.y + (k - n) * config.step_m;
  }
  // Per yaw step its best grid pose (cell = cy * side + cx); the reduction over yaws is
  // sequential (deterministic).
  std::vector<double> best_score(yaws, -1.0);
  std::vector<int64_t> best_cell(yaws, 0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int32_t a = 0; a < yaws; ++a) {
    const double yaw = guess.yaw + (a - m) * config.yaw_step_rad;
    const double c = std::cos(yaw), s = std::sin(yaw);
    std::vector<double> scores(static_cast<size_t>(side) * side, 0.0);
    std::vector<int64_t> xs(side), ys(side);
    for (const Eigen::Vector2d& column : columns) {
      const Eigen::Vector2d p(c * column.x() - s * column.y(), s * column.x() + c * column.y());
      cells_along_axis(p.x(), offsets_x, fixed.cell_m(), table.origin_x, table.size_x, &xs);
      cells_along_axis(p.y(), offsets_y, fixed.cell_m(), table.origin_y, table.size_y, &ys);
      add_column_scores(table, xs, ys, &scores);
    }
    for (int64_t cell = 0; cell < int64_t(side) * side; ++cell) {
      if (scores[cell] > best_score[a]) {
        best_score[a] = scores[cell];
        best_cell[a] = cell;
      }
    }
  }
  WallMatch match;
  match.T_fixed_moving = guess;
  match.score = -1.0;
  for (int32_t a = 0; a < yaws; ++a) {
    if (best_score[a] <= match.score) continue;
    match.score = best_score[a];
    match.T_fixed_moving.x = guess.x + (best_cell[a] % side - n) * config.step_m;
    match.T_fixed_moving.y = guess.y + (best_cell[a] / side - n) * config.step_m;
    match.T_fixed_moving.yaw = guess.yaw + (a - m) * config.yaw_step_rad;
  }
  match.score = std::max(match.score, 0.0);
  return match;
}

}  // namespace pipeline
}  // namespace covox

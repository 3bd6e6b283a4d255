#include "covoxslam/pipeline/wall_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <utility>

#include "covoxslam/backend/registration.h"
#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/internal/wall_search.h"

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

void WallMapCache::release() {
  std::lock_guard<std::mutex> lock(mutex_);
  walls_.reset();
}

bool WallMapCache::holds_walls() {
  std::lock_guard<std::mutex> lock(mutex_);
  return walls_ != nullptr;
}

double WallMap::distance_m(double x, double y) const {
  const int64_t ix = static_cast<int64_t>(std::floor(x / cell_m_)) - origin_x_;
  const int64_t iy = static_cast<int64_t>(std::floor(y / cell_m_)) - origin_y_;
  if (ix < 0 || iy < 0 || ix >= size_x_ || iy >= size_y_) return cap_m_;
  return distance_[static_cast<size_t>(iy) * size_x_ + static_cast<size_t>(ix)];
}

namespace {

// Every grid pose's score (wall_search.h), on the stream's device.
std::vector<double> grid_scores(const internal::WallSearchGrid& grid,
                                const WallMap::CellTable& table, double cell_m,
                                const std::vector<Eigen::Vector2d>& columns, double guess_yaw,
                                double yaw_step_rad, const std::vector<double>& offsets_x,
                                const std::vector<double>& offsets_y, const Stream& stream) {
  const int32_t m = (grid.yaws - 1) / 2;
  // Turned on the host, so both backends look the same coordinates up.
  std::vector<double> rotated;
  rotated.reserve(static_cast<size_t>(grid.yaws) * columns.size() * 2);
  for (int32_t a = 0; a < grid.yaws; ++a) {
    const double yaw = guess_yaw + (a - m) * yaw_step_rad;
    const double c = std::cos(yaw), s = std::sin(yaw);
    for (const Eigen::Vector2d& column : columns) {
      rotated.push_back(c * column.x() - s * column.y());
      rotated.push_back(s * column.x() + c * column.y());
    }
  }
  const Device device = stream.device();
  const auto inside = Buffer<double>::from_host(device, table.inside, stream);
  const auto device_rotated = Buffer<double>::from_host(device, rotated, stream);
  const auto device_offsets_x = Buffer<double>::from_host(device, offsets_x, stream);
  const auto device_offsets_y = Buffer<double>::from_host(device, offsets_y, stream);
  const size_t along = static_cast<size_t>(grid.yaws) * grid.columns * grid.side;
  Buffer<int32_t> cells_x(device, along), cells_y(device, along);
  Buffer<double> scores(device, static_cast<size_t>(grid.yaws) * grid.side * grid.side);
  const internal::WallCellTable cell_table{inside.data(),  table.outside, table.origin_x,
                                           table.origin_y, table.size_x,  table.size_y,
                                           cell_m};
  dispatch(device, [&](auto backend) {
    internal::wall_search_cells(backend, stream, grid, cell_table, device_rotated.data(),
                                device_offsets_x.data(), device_offsets_y.data(), cells_x.data(),
                                cells_y.data());
    internal::wall_search_scores(backend, stream, grid, cell_table, cells_x.data(), cells_y.data(),
                                 scores.data());
  });
  return scores.to_host(stream);
}

}  // namespace

WallMatch match_walls(const WallMap& moving, const WallMap& fixed, const backend::Pose4Dof& guess,
                      const WallSearchConfig& config, const Stream& stream) {
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
  const internal::WallSearchGrid grid{yaws, static_cast<int32_t>(columns.size()), side};
  const std::vector<double> scores = grid_scores(grid, table, fixed.cell_m(), columns, guess.yaw,
                                                 config.yaw_step_rad, offsets_x, offsets_y, stream);
  // Per yaw step its best grid pose (cell = cy * side + cx), then the best over the yaws, both in
  // order: ties go to the first grid pose.
  std::vector<double> best_score(yaws, -1.0);
  std::vector<int64_t> best_cell(yaws, 0);
  const int64_t cells = int64_t(side) * side;
  for (int32_t a = 0; a < yaws; ++a) {
    for (int64_t cell = 0; cell < cells; ++cell) {
      if (scores[a * cells + cell] > best_score[a]) {
        best_score[a] = scores[a * cells + cell];
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

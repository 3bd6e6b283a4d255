#pragma once
// Definitions for wall_search.h; included only by the two backend instantiation files.
#include <cmath>
#include <type_traits>

#include "covoxslam/core/parallel.h"
#include "covoxslam/pipeline/internal/wall_search.h"

namespace covox::pipeline::internal {

template <class Backend>
void wall_search_cells(Backend backend, const Stream& stream, WallSearchGrid grid,
                       WallCellTable table, const double* rotated_m, const double* offsets_x_m,
                       const double* offsets_y_m, int32_t* cells_x, int32_t* cells_y) {
  const int64_t pairs = static_cast<int64_t>(grid.yaws) * grid.columns;
  parallel_for(backend, stream, pairs, [=] COVOX_HD(int64_t i) {
    const double x = rotated_m[2 * i], y = rotated_m[2 * i + 1];
    for (int32_t k = 0; k < grid.side; ++k) {
      // As WallMap::distance_m finds a point's cell.
      const int64_t cx =
          static_cast<int64_t>(floor((x + offsets_x_m[k]) / table.cell_m)) - table.origin_x;
      const int64_t cy =
          static_cast<int64_t>(floor((y + offsets_y_m[k]) / table.cell_m)) - table.origin_y;
      cells_x[i * grid.side + k] = cx >= 0 && cx < table.size_x ? static_cast<int32_t>(cx) : -1;
      cells_y[i * grid.side + k] = cy >= 0 && cy < table.size_y ? static_cast<int32_t>(cy) : -1;
    }
  });
}

// One grid pose's sum (kWholeRow false) or a row of x offsets' sums (kWholeRow true: each
// column's x cells read once, in order), written at `out`. Either way every pose's sum is the
// same additions in column order.
template <bool kWholeRow>
COVOX_HD_INLINE void score_grid_item(const WallSearchGrid& grid, const WallCellTable& table,
                                     const int32_t* cells_x, const int32_t* cells_y, int64_t a,
                                     int64_t cy, int32_t first_x, double* out) {
  double sum = 0.0;
  if constexpr (kWholeRow) {
    for (int32_t k = 0; k < grid.side; ++k) out[k] = 0.0;
  }
  for (int32_t c = 0; c < grid.columns; ++c) {
    const int64_t along = (a * grid.columns + c) * grid.side;
    const int32_t y = cells_y[along + cy];
    const double* cells = y >= 0 ? table.inside + static_cast<int64_t>(y) * table.size_x : nullptr;
    const int32_t* xs = cells_x + along + first_x;
    if constexpr (kWholeRow) {
      for (int32_t k = 0; k < grid.side; ++k)
        out[k] += cells && xs[k] >= 0 ? cells[xs[k]] : table.outside;
    } else {
      sum += cells && xs[0] >= 0 ? cells[xs[0]] : table.outside;
    }
  }
  if constexpr (!kWholeRow) out[0] = sum;
}

template <class Backend>
void wall_search_scores(Backend backend, const Stream& stream, WallSearchGrid grid,
                        WallCellTable table, const int32_t* cells_x, const int32_t* cells_y,
                        double* scores) {
  // A CPU thread takes a row of x offsets, a GPU thread one grid pose.
  constexpr bool kWholeRow = std::is_same_v<Backend, CpuBackend>;
  const int32_t items_per_row = kWholeRow ? 1 : grid.side;
  const int64_t items = static_cast<int64_t>(grid.yaws) * grid.side * items_per_row;
  parallel_for(backend, stream, items, [=] COVOX_HD(int64_t item) {
    const int64_t row = item / items_per_row;  // a * side + cy
    const int32_t first_x = static_cast<int32_t>(item % items_per_row);
    score_grid_item<kWholeRow>(grid, table, cells_x, cells_y, row / grid.side, row % grid.side,
                               first_x, scores + row * grid.side + first_x);
  });
}

#define COVOX_INSTANTIATE_WALL_SEARCH(Backend)                                                     \
  template void wall_search_cells<Backend>(Backend, const Stream&, WallSearchGrid, WallCellTable,  \
                                           const double*, const double*, const double*, int32_t*,  \
                                           int32_t*);                                              \
  template void wall_search_scores<Backend>(Backend, const Stream&, WallSearchGrid, WallCellTable, \
                                            const int32_t*, const int32_t*, double*);

}  // namespace covox::pipeline::internal

#pragma once
// The wall search's grid scores (wall_map.h) on the caller's device. Defined in
// wall_search_impl.h, instantiated per backend.
//
// Grid pose (a, cy, cx): yaw step a, y offset cy, x offset cx. A moved column's table cell along
// each axis depends on one offset only, so the cells are found once per (yaw, column, offset) and
// a grid pose's score is the sum over the columns, in their order, of the fixed map's cell value
// at (x cell, y cell): the outside value where either cell is outside the table.
#include <cstdint>

#include "covoxslam/core/stream.h"

namespace covox::pipeline::internal {

struct WallSearchGrid {
  int32_t yaws = 0, columns = 0, side = 0;  // side: offsets along each axis
};

// The fixed map's cell values: row-major, size_x cells a row.
struct WallCellTable {
  const double* inside = nullptr;
  double outside = 0.0;
  int32_t origin_x = 0, origin_y = 0, size_x = 0, size_y = 0;
  double cell_m = 0.0;
};

// Per (yaw, column): the table cell of every offset along x and y, -1 outside the table.
// rotated_m: per (yaw, column) the column turned by the yaw (x, y); offsets_*_m: side each.
// cells_x and cells_y: [yaw][column][offset].
template <class Backend>
void wall_search_cells(Backend backend, const Stream& stream, WallSearchGrid grid,
                       WallCellTable table, const double* rotated_m, const double* offsets_x_m,
                       const double* offsets_y_m, int32_t* cells_x, int32_t* cells_y);

// scores[(a * side + cy) * side + cx]: the grid pose's sum over the columns.
template <class Backend>
void wall_search_scores(Backend backend, const Stream& stream, WallSearchGrid grid,
                        WallCellTable table, const int32_t* cells_x, const int32_t* cells_y,
                        double* scores);

}  // namespace covox::pipeline::internal

#pragma once
// The sparsity pattern of the pose-graph normal equations H = J^T J (D x D blocks), built once on
// the host per graph and uploaded. Every block and gradient entry is then a sum over a fixed list
// of constraint terms, so assembly is one parallel gather per entry: no atomics, and the same
// summation order on both backends.
#include <cstdint>
#include <utility>
#include <vector>

namespace covox {
namespace backend {

struct BlockSparseStructure {
  int32_t vertex_count = 0;
  int32_t fixed_vertex = -1;  // its block is the identity and its gradient zero: it never moves

  // Diagonal block and gradient of vertex v: terms [diag_offsets[v], diag_offsets[v + 1]) of
  // diag_terms; a term is 2 * constraint + side (0: the constraint's `from`, 1: its `to`).
  std::vector<int32_t> diag_offsets;
  std::vector<int32_t> diag_terms;

  // Off-diagonal block b, H(row, col) with row < col: terms [off_offsets[b], off_offsets[b + 1])
  // of off_terms; a term is 2 * constraint + swapped (swapped: the constraint's `from` is `col`,
  // so the term is Jto^T Jfrom instead of Jfrom^T Jto).
  std::vector<int32_t> off_row;
  std::vector<int32_t> off_col;
  std::vector<int32_t> off_offsets;
  std::vector<int32_t> off_terms;

  // For the product H x, row by row: the off-diagonal blocks in block row v are entries
  // [row_offsets[v], row_offsets[v + 1]) of row_entries (2 * block + transposed) and row_columns
  // (the vertex the block multiplies).
  std::vector<int32_t> row_offsets;
  std::vector<int32_t> row_entries;
  std::vector<int32_t> row_columns;

  // chain_blocks[v]: the off-diagonal block (v, v + 1), or -1 when no constraint joins them (the
  // odometry chain of the chain preconditioner).
  std::vector<int32_t> chain_blocks;

  int64_t off_block_count() const { return static_cast<int64_t>(off_row.size()); }
};

// `edges[k]` = (from, to) of constraint k; to = -1 for unary constraints. Terms that touch the
// fixed vertex are left out (its update is zero by construction).
BlockSparseStructure build_block_sparse_structure(
    const std::vector<std::pair<int32_t, int32_t>>& edges, int32_t vertex_count,
    int32_t fixed_vertex);

}  // namespace backend
}  // namespace covox

#include "covoxslam/backend/internal/block_sparse_structure.h"

#include <algorithm>
#include <map>

namespace covox {
namespace backend {
namespace {

// Counting sort of (key, value) pairs into CSR form; values keep their input order per key.
void to_csr(const std::vector<std::pair<int32_t, int32_t>>& pairs, int32_t key_count,
            std::vector<int32_t>* offsets, std::vector<int32_t>* values) {
  offsets->assign(static_cast<size_t>(key_count) + 1, 0);
  for (const auto& [key, value] : pairs) ++(*offsets)[key + 1];
  for (int32_t k = 0; k < key_count; ++k) (*offsets)[k + 1] += (*offsets)[k];
  values->resize(pairs.size());
  std::vector<int32_t> cursor(offsets->begin(), offsets->end() - 1);
  for (const auto& [key, value] : pairs) (*values)[cursor[key]++] = value;
}

}  // namespace

BlockSparseStructure build_block_sparse_structure(
    const std::vector<std::pair<int32_t, int32_t>>& edges, int32_t vertex_count,
    int32_t fixed_vertex) {
  BlockSparseStructure s;
  s.vertex_count = vertex_count;
  s.fixed_vertex = fixed_vertex;
  const auto free_vertex = [&](int32_t v) { return v >= 0 && v != fixed_vertex; };

  std::vector<std::pair<int32_t, int32_t>> diag_pairs;
  std::map<std::pair<int32_t, int32_t>, int32_t>
      block_of_pair;  // ordered: blocks sorted by (row, col)
  for (int32_t k = 0; k < static_cast<int32_t>(edges.size()); ++k) {
    const auto [from, to] = edges[k];
    if (free_vertex(from)) diag_pairs.emplace_back(from, 2 * k);
    if (free_vertex(to)) diag_pairs.emplace_back(to, 2 * k + 1);
    if (free_vertex(from) && free_vertex(to)) block_of_pair.emplace(std::minmax(from, to), 0);
  }
  to_csr(diag_pairs, vertex_count, &s.diag_offsets, &s.diag_terms);

  int32_t next_block = 0;
  for (auto& [pair, block] : block_of_pair) {
    block = next_block++;
    s.off_row.push_back(pair.first);
    s.off_col.push_back(pair.second);
  }
  std::vector<std::pair<int32_t, int32_t>> off_pairs;
  for (int32_t k = 0; k < static_cast<int32_t>(edges.size()); ++k) {
    const auto [from, to] = edges[k];
    if (!free_vertex(from) || !free_vertex(to)) continue;
    const int32_t block = block_of_pair.at(std::minmax(from, to));
    off_pairs.emplace_back(block, 2 * k + (from > to ? 1 : 0));
  }
  to_csr(off_pairs, next_block, &s.off_offsets, &s.off_terms);
  s.chain_blocks.assign(static_cast<size_t>(std::max(vertex_count, 1)), -1);
  for (int32_t v = 0; v + 1 < vertex_count; ++v) {
    const auto found = block_of_pair.find({v, v + 1});
    if (found != block_of_pair.end()) s.chain_blocks[v] = found->second;
  }

  std::vector<std::pair<int32_t, int32_t>> row_pairs;  // (row, 2 * block + transposed)
  for (int32_t b = 0; b < next_block; ++b) {
    row_pairs.emplace_back(s.off_row[b], 2 * b);
    row_pairs.emplace_back(s.off_col[b], 2 * b + 1);
  }
  to_csr(row_pairs, vertex_count, &s.row_offsets, &s.row_entries);
  s.row_columns.resize(s.row_entries.size());
  for (size_t e = 0; e < s.row_entries.size(); ++e) {
    const int32_t b = s.row_entries[e] / 2;
    s.row_columns[e] = (s.row_entries[e] & 1) ? s.off_row[b] : s.off_col[b];
  }
  return s;
}

}  // namespace backend
}  // namespace covox

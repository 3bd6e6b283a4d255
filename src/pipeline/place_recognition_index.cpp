// The ring-key index of place recognition: a k-d tree rebuilt from scratch every kMaxUnindexed
// insertions, plus the insertions since, searched one by one.
#include <algorithm>
#include <limits>
#include <numeric>
#include <utility>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/place_recognition.h"

namespace covox {
namespace pipeline {

namespace {

double squared_distance(const std::vector<float>& a, const std::vector<float>& b) {
  double sum = 0.0;
  for (size_t k = 0; k < a.size(); ++k) {
    const double d = static_cast<double>(a[k]) - b[k];
    sum += d * d;
  }
  return sum;
}

}  // namespace

// The k best (squared distance, id) found so far, sorted; `worst()` prunes the tree's branches.
struct RingKeyIndex::Search {
  const std::vector<float>* key;
  size_t k;
  int64_t max_id;
  std::vector<std::pair<double, int64_t>> best;
  double worst() const {
    return best.size() < k ? std::numeric_limits<double>::infinity() : best.back().first;
  }
  void offer(double distance, int64_t id) {
    if (id > max_id) return;
    const std::pair<double, int64_t> item(distance, id);
    if (best.size() == k && !(item < best.back())) return;
    best.insert(std::upper_bound(best.begin(), best.end(), item), item);
    if (best.size() > k) best.pop_back();
  }
};

void RingKeyIndex::clear() {
  ids_.clear();
  keys_.clear();
  nodes_.clear();
  root_ = -1;
  indexed_ = 0;
}

void RingKeyIndex::add(int64_t id, const std::vector<float>& key) {
  if (!keys_.empty() && key.size() != keys_.front().size()) {
    throw Error("place recognition: ring keys of different lengths");
  }
  ids_.push_back(id);
  keys_.push_back(key);
  if (keys_.size() - indexed_ < kMaxUnindexed) return;
  std::vector<int32_t> items(keys_.size());
  std::iota(items.begin(), items.end(), 0);
  nodes_.clear();
  nodes_.reserve(items.size());
  root_ = build(items, 0, items.size(), 0);
  indexed_ = keys_.size();
}

int32_t RingKeyIndex::build(std::vector<int32_t>& items, size_t begin, size_t end, int depth) {
  if (begin >= end) return -1;
  const int32_t dimension = static_cast<int32_t>(depth % static_cast<int>(keys_.front().size()));
  const size_t middle = begin + (end - begin) / 2;
  std::nth_element(items.begin() + begin, items.begin() + middle, items.begin() + end,
                   [&](int32_t a, int32_t b) {
                     const float va = keys_[a][dimension], vb = keys_[b][dimension];
                     return va < vb || (va == vb && a < b);
                   });
  const int32_t node = static_cast<int32_t>(nodes_.size());
  nodes_.push_back(Node{items[middle], dimension, -1, -1});
  const int32_t left = build(items, begin, middle, depth + 1);
  const int32_t right = build(items, middle + 1, end, depth + 1);
  nodes_[node].left = left;
  nodes_[node].right = right;
  return node;
}

void RingKeyIndex::search(int32_t node, Search* state) const {
  if (node < 0) return;
  const Node& n = nodes_[node];
  const std::vector<float>& key = *state->key;
  state->offer(squared_distance(key, keys_[n.item]), ids_[n.item]);
  const double along = static_cast<double>(key[n.dimension]) - keys_[n.item][n.dimension];
  const int32_t near_side = along < 0.0 ? n.left : n.right;
  const int32_t far_side = along < 0.0 ? n.right : n.left;
  search(near_side, state);
  if (along * along <= state->worst()) search(far_side, state);
}

std::vector<int64_t> RingKeyIndex::nearest(const std::vector<float>& key, size_t k,
                                           int64_t max_id) const {
  std::vector<int64_t> result;
  if (k == 0 || keys_.empty()) return result;
  if (key.size() != keys_.front().size()) {
    throw Error("place recognition: ring keys of different lengths");
  }
  Search state{&key, k, max_id, {}};
  search(root_, &state);
  for (size_t i = indexed_; i < keys_.size(); ++i)
    state.offer(squared_distance(key, keys_[i]), ids_[i]);
  for (const auto& item : state.best) result.push_back(item.second);
  return result;
}

}  // namespace pipeline
}  // namespace covox

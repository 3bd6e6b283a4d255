#include "covoxslam/io/rosbag_tf_buffer.h"

#include <algorithm>
#include <cstdio>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace rosbag {
namespace {

std::string format_stamp(double stamp_s) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.6f s", stamp_s);
  return text;
}

}  // namespace

void TfBuffer::add(const TransformStamped& transform, bool is_static) {
  add(transform.header.frame_id, transform.child_frame_id, transform.header.stamp.to_seconds(),
      transform.T_parent_child, is_static);
}

void TfBuffer::add(const std::string& parent, const std::string& child, double stamp_s,
                   const Eigen::Isometry3d& T_parent_child, bool is_static) {
  // tf2 strips a leading slash from frame ids ("/odom" and "odom" are the same frame).
  const std::string parent_id = !parent.empty() && parent[0] == '/' ? parent.substr(1) : parent;
  const std::string child_id = !child.empty() && child[0] == '/' ? child.substr(1) : child;
  if (parent_id == child_id) throw Error("tf: frame '" + child_id + "' cannot be its own parent");
  Edge& edge = edges_[child_id];
  if (!edge.parent.empty() && edge.parent != parent_id) {
    throw Error("tf: frame '" + child_id + "' has two parents, '" + edge.parent + "' and '" +
                parent_id + "'");
  }
  edge.parent = parent_id;
  if (is_static) {
    edge.is_static = true;
    edge.samples.assign(1, Sample{stamp_s, T_parent_child});
    return;
  }
  if (edge.is_static) return;  // a static transform is not overridden by a dynamic one
  const auto after =
      std::upper_bound(edge.samples.begin(), edge.samples.end(), stamp_s,
                       [](double stamp, const Sample& sample) { return stamp < sample.stamp_s; });
  edge.samples.insert(after, Sample{stamp_s, T_parent_child});
}

bool TfBuffer::has_frame(const std::string& frame) const {
  if (edges_.count(frame) != 0) return true;
  for (const auto& edge : edges_) {
    if (edge.second.parent == frame) return true;
  }
  return false;
}

size_t TfBuffer::dynamic_sample_count() const {
  size_t count = 0;
  for (const auto& edge : edges_) {
    if (!edge.second.is_static) count += edge.second.samples.size();
  }
  return count;
}

bool TfBuffer::interpolate(const Edge& edge, double stamp_s, Eigen::Isometry3d* T_parent_child) {
  if (edge.is_static) {
    *T_parent_child = edge.samples.front().T_parent_child;
    return true;
  }
  if (edge.samples.empty() || stamp_s < edge.samples.front().stamp_s ||
      stamp_s > edge.samples.back().stamp_s)
    return false;
  const auto after =
      std::lower_bound(edge.samples.begin(), edge.samples.end(), stamp_s,
                       [](const Sample& sample, double stamp) { return sample.stamp_s < stamp; });
  if (after->stamp_s == stamp_s || after == edge.samples.begin()) {
    *T_parent_child = after->T_parent_child;
    return true;
  }
  const Sample& a = *(after - 1);
  const Sample& b = *after;
  const double t = (stamp_s - a.stamp_s) / (b.stamp_s - a.stamp_s);
  const Eigen::Quaterniond qa(a.T_parent_child.linear()), qb(b.T_parent_child.linear());
  T_parent_child->setIdentity();
  T_parent_child->linear() = qa.slerp(t, qb).normalized().toRotationMatrix();
  T_parent_child->translation() =
      (1.0 - t) * a.T_parent_child.translation() + t * b.T_parent_child.translation();
  return true;
}

std::vector<std::string> TfBuffer::ancestors(const std::string& frame) const {
  std::vector<std::string> chain{frame};
  for (auto edge = edges_.find(frame); edge != edges_.end(); edge = edges_.find(chain.back())) {
    chain.push_back(edge->second.parent);
    if (chain.size() > edges_.size() + 1) return {};  // a loop: no frame has a root
  }
  return chain;
}

bool TfBuffer::transform_to_ancestor(const std::string& frame, const std::string& ancestor,
                                     double stamp_s, Eigen::Isometry3d* T_ancestor_frame,
                                     std::string* reason) const {
  T_ancestor_frame->setIdentity();
  for (std::string current = frame; current != ancestor;) {
    const Edge& edge = edges_.at(current);
    Eigen::Isometry3d T_parent_child;
    if (!interpolate(edge, stamp_s, &T_parent_child)) {
      if (reason) {
        *reason =
            "tf: no transform '" + edge.parent + "' -> '" + current + "' at " +
            format_stamp(stamp_s) +
            (edge.samples.empty()
                 ? std::string(" (none received)")
                 : " (received from " + format_stamp(edge.samples.front().stamp_s) + " to " +
                       format_stamp(edge.samples.back().stamp_s) + "; tf does not extrapolate)");
      }
      return false;
    }
    *T_ancestor_frame = T_parent_child * *T_ancestor_frame;
    current = edge.parent;
  }
  return true;
}

bool TfBuffer::lookup(const std::string& target, const std::string& source, double stamp_s,
                      Eigen::Isometry3d* T_target_source, std::string* reason) const {
  const std::string target_id = !target.empty() && target[0] == '/' ? target.substr(1) : target;
  const std::string source_id = !source.empty() && source[0] == '/' ? source.substr(1) : source;
  for (const std::string& frame : {target_id, source_id}) {
    if (!has_frame(frame)) {
      if (reason) *reason = "tf: unknown frame '" + frame + "'";
      return false;
    }
  }
  const std::vector<std::string> source_chain = ancestors(source_id);
  const std::vector<std::string> target_chain = ancestors(target_id);
  if (source_chain.empty() || target_chain.empty()) {
    if (reason)
      *reason = "tf: the frames above '" + (source_chain.empty() ? source_id : target_id) +
                "' form a loop";
    return false;
  }
  // The lowest common ancestor: the first frame of the source's chain that the target's holds.
  // Only the transforms below it are evaluated, as tf2 does: a dynamic transform above it that
  // does not reach the stamp does not matter.
  for (const std::string& ancestor : source_chain) {
    if (std::find(target_chain.begin(), target_chain.end(), ancestor) == target_chain.end())
      continue;
    Eigen::Isometry3d T_ancestor_source, T_ancestor_target;
    if (!transform_to_ancestor(source_id, ancestor, stamp_s, &T_ancestor_source, reason))
      return false;
    if (!transform_to_ancestor(target_id, ancestor, stamp_s, &T_ancestor_target, reason))
      return false;
    *T_target_source = T_ancestor_target.inverse() * T_ancestor_source;
    return true;
  }
  if (reason) {
    *reason = "tf: frames '" + target_id + "' and '" + source_id + "' are not connected (roots '" +
              target_chain.back() + "' and '" + source_chain.back() + "')";
  }
  return false;
}

}  // namespace rosbag
}  // namespace io
}  // namespace covox

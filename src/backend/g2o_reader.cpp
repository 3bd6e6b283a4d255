#include "covoxslam/backend/g2o_reader.h"

#include <Eigen/Geometry>
#include <charconv>
#include <fstream>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "covoxslam/core/error.h"
#include "covoxslam/core/number_text.h"

namespace covox {
namespace backend {
namespace {

constexpr size_t kVertexFields = 8;         // id + 3 + 4
constexpr size_t kEdgeFields = 2 + 7 + 21;  // i j + pose + upper triangle

std::vector<std::string_view> tokens_of(std::string_view line) {
  std::vector<std::string_view> tokens;
  size_t pos = 0;
  while (pos < line.size()) {
    while (pos < line.size() && (line[pos] == ' ' || line[pos] == '\t' || line[pos] == '\r')) ++pos;
    size_t end = pos;
    while (end < line.size() && line[end] != ' ' && line[end] != '\t' && line[end] != '\r') ++end;
    if (end > pos) tokens.push_back(line.substr(pos, end - pos));
    pos = end;
  }
  return tokens;
}

class LineParser {
 public:
  LineParser(const std::string& source, int line_number) : source_(source), line_(line_number) {}

  [[noreturn]] void fail(const std::string& what) const {
    throw Error(source_ + ":" + std::to_string(line_) + ": " + what);
  }
  // covox::parse_double ignores the locale, unlike strtod.
  double number(std::string_view token) const {
    double value = 0.0;
    if (!parse_double(token, &value)) fail("'" + std::string(token) + "' is not a number");
    return value;
  }
  int64_t integer(std::string_view token) const {
    int64_t value = 0;
    const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
    if (error != std::errc() || end != token.data() + token.size()) {
      fail("'" + std::string(token) + "' is not an integer vertex id");
    }
    return value;
  }
  Se3Pose pose(const std::vector<std::string_view>& t, size_t first) const {
    double v[7];
    for (int k = 0; k < 7; ++k) v[k] = number(t[first + k]);
    const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
    const double norm = q.norm();
    if (!(norm > 1e-6) || !std::isfinite(norm))
      fail("the quaternion has zero or non-finite length");
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(v[k])) fail("the translation is not finite");
    }
    return make_se3_pose(Eigen::Vector3d(v[0], v[1], v[2]), q);
  }

 private:
  const std::string& source_;
  int line_;
};

struct PendingEdge {
  int line = 0;
  int64_t from_id = 0, to_id = 0;
  Se3Pose measurement;
  Eigen::Matrix<double, 6, 6> information;
};

// Collects a g2o file's lines; edges and FIX are resolved once every vertex is known, because
// g2o files may list them in any order.
class G2oBuilder {
 public:
  explicit G2oBuilder(const std::string& source_name) : source_(source_name) {}

  void add_line(const std::vector<std::string_view>& tokens, int line_number) {
    const LineParser parse(source_, line_number);
    const std::string_view tag = tokens[0];
    if (tag == "VERTEX_SE3:QUAT") {
      add_vertex(parse, tokens);
    } else if (tag == "EDGE_SE3:QUAT") {
      add_edge(parse, tokens, line_number);
    } else if (tag == "FIX") {
      if (tokens.size() != 2) parse.fail("FIX needs one vertex id");
      fixes_.emplace_back(line_number, parse.integer(tokens[1]));
    } else {
      parse.fail("unknown g2o tag '" + std::string(tag) +
                 "' (this reader handles VERTEX_SE3:QUAT, EDGE_SE3:QUAT and FIX)");
    }
  }

  G2oGraph finish() {
    if (result_.graph.poses.empty())
      throw Error(source_ + ": no VERTEX_SE3:QUAT line: not an SE(3) g2o graph");
    for (const PendingEdge& edge : edges_) resolve_edge(edge);
    result_.graph.fixed_vertex = 0;
    if (!fixes_.empty()) {
      const auto fixed = index_of_id_.find(fixes_.front().second);
      if (fixed == index_of_id_.end()) {
        LineParser(source_, fixes_.front().first)
            .fail("FIX names vertex " + std::to_string(fixes_.front().second) +
                  ", which has no VERTEX line");
      }
      result_.graph.fixed_vertex = fixed->second;
    }
    return std::move(result_);
  }

 private:
  void add_vertex(const LineParser& parse, const std::vector<std::string_view>& tokens) {
    const size_t fields = tokens.size() - 1;
    if (fields != kVertexFields) {
      parse.fail("VERTEX_SE3:QUAT needs " + std::to_string(kVertexFields) +
                 " fields (id x y z qx qy qz qw), found " + std::to_string(fields));
    }
    const int64_t id = parse.integer(tokens[1]);
    const auto inserted =
        index_of_id_.emplace(id, static_cast<int32_t>(result_.graph.poses.size()));
    if (!inserted.second) parse.fail("vertex id " + std::to_string(id) + " appears twice");
    result_.graph.poses.push_back(parse.pose(tokens, 2));
    result_.vertex_ids.push_back(id);
  }

  void add_edge(const LineParser& parse, const std::vector<std::string_view>& tokens,
                int line_number) {
    const size_t fields = tokens.size() - 1;
    if (fields != kEdgeFields) {
      parse.fail("EDGE_SE3:QUAT needs " + std::to_string(kEdgeFields) +
                 " fields (i j x y z qx qy qz qw and 21 information entries), found " +
                 std::to_string(fields));
    }
    PendingEdge edge;
    edge.line = line_number;
    edge.from_id = parse.integer(tokens[1]);
    edge.to_id = parse.integer(tokens[2]);
    edge.measurement = parse.pose(tokens, 3);
    size_t next = 10;
    for (int r = 0; r < 6; ++r) {
      for (int c = r; c < 6; ++c) {
        edge.information(r, c) = edge.information(c, r) = parse.number(tokens[next++]);
      }
    }
    edges_.push_back(edge);
  }

  void resolve_edge(const PendingEdge& edge) {
    const LineParser parse(source_, edge.line);
    const auto from = index_of_id_.find(edge.from_id);
    const auto to = index_of_id_.find(edge.to_id);
    if (from == index_of_id_.end())
      parse.fail("edge names vertex " + std::to_string(edge.from_id) +
                 ", which has no VERTEX line");
    if (to == index_of_id_.end())
      parse.fail("edge names vertex " + std::to_string(edge.to_id) + ", which has no VERTEX line");
    if (from->second == to->second)
      parse.fail("edge joins vertex " + std::to_string(edge.from_id) + " to itself");
    try {
      result_.graph.constraints.push_back(
          make_se3_constraint(from->second, to->second, edge.measurement, edge.information));
    } catch (const Error& error) {
      parse.fail(error.what());
    }
  }

  const std::string& source_;
  G2oGraph result_;
  std::unordered_map<int64_t, int32_t> index_of_id_;
  std::vector<PendingEdge> edges_;
  std::vector<std::pair<int, int64_t>> fixes_;
};

}  // namespace

G2oGraph parse_g2o(const std::string& text, const std::string& source_name) {
  G2oBuilder builder(source_name);
  std::istringstream stream(text);
  std::string line;
  int line_number = 0;
  while (std::getline(stream, line)) {
    ++line_number;
    const auto tokens = tokens_of(line);
    if (tokens.empty() || tokens[0].front() == '#') continue;
    builder.add_line(tokens, line_number);
  }
  return builder.finish();
}

G2oGraph read_g2o(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw Error(path + ": cannot open the g2o file (does it exist and is it readable?)");
  std::ostringstream contents;
  contents << file.rdbuf();
  if (file.bad()) throw Error(path + ": read error");
  return parse_g2o(contents.str(), path);
}

}  // namespace backend
}  // namespace covox

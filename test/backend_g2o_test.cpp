// The g2o reader: a small valid file, the gauge, and clear errors naming file and line.
#include <gtest/gtest.h>

#include <string>

#include "covoxslam/backend/g2o_reader.h"
#include "covoxslam/core/error.h"

namespace covox {
namespace backend {
namespace {

const char* kIdentityInformation = "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1";

std::string valid_graph() {
  return std::string("# a comment\n") + "VERTEX_SE3:QUAT 10 0 0 0 0 0 0 1\n" +
         "VERTEX_SE3:QUAT 20 1 0 0 0 0 0.7071067811865476 0.7071067811865476\n\n" +
         "EDGE_SE3:QUAT 10 20 1 0 0 0 0 0.7071067811865476 0.7071067811865476 " +
         kIdentityInformation + "\n";
}

// The message of the covox::Error that parse_g2o throws on `text` ("" when it does not throw).
std::string error_of(const std::string& text) {
  try {
    parse_g2o(text, "graph.g2o");
  } catch (const Error& error) {
    return error.what();
  }
  return "";
}

TEST(BackendG2o, ReadsVerticesEdgesAndInformation) {
  const G2oGraph g = parse_g2o(valid_graph(), "graph.g2o");
  ASSERT_EQ(g.graph.poses.size(), 2u);
  ASSERT_EQ(g.vertex_ids, (std::vector<int64_t>{10, 20}));
  ASSERT_EQ(g.graph.constraints.size(), 1u);
  EXPECT_EQ(g.graph.constraints[0].from, 0);
  EXPECT_EQ(g.graph.constraints[0].to, 1);
  EXPECT_EQ(g.graph.fixed_vertex, 0);
  EXPECT_NEAR(g.graph.poses[1].rotation[2], 0.7071067811865476, 1e-15);
  // Identity information: the square root is the identity (up to the eigenvector basis sign).
  Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>> s(
      g.graph.constraints[0].sqrt_information);
  EXPECT_LT(((s.transpose() * s) - Eigen::Matrix<double, 6, 6>::Identity()).norm(), 1e-12);
  // The measurement equals T_i^-1 T_j of the vertices: zero cost.
  EXPECT_NEAR(pose_graph_cost(g.graph), 0.0, 1e-20);
}

TEST(BackendG2o, FixSetsTheGauge) {
  const G2oGraph g = parse_g2o(valid_graph() + "FIX 20\n", "graph.g2o");
  EXPECT_EQ(g.graph.fixed_vertex, 1);
}

TEST(BackendG2o, UpperTriangleFillsASymmetricInformation) {
  // Information with off-diagonal terms: S^T S must reproduce it.
  const std::string info = "4 1 0 0 0 0 5 0 0 0 0 6 0 0 0 7 0 0 8 0 9";
  const G2oGraph g = parse_g2o(
      "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n"
      "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 " +
          info + "\n",
      "graph.g2o");
  Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>> s(
      g.graph.constraints[0].sqrt_information);
  const Eigen::Matrix<double, 6, 6> information = s.transpose() * s;
  EXPECT_NEAR(information(0, 1), 1.0, 1e-12);
  EXPECT_NEAR(information(1, 0), 1.0, 1e-12);
  EXPECT_NEAR(information(5, 5), 9.0, 1e-12);
}

TEST(BackendG2o, ErrorsNameFileAndLine) {
  EXPECT_NE(error_of(valid_graph() + "VERTEX_SE2 3 0 0 0\n")
                .find("graph.g2o:6: unknown g2o tag 'VERTEX_SE2'"),
            std::string::npos);
  EXPECT_NE(error_of("VERTEX_SE3:QUAT 0 0 0 0 0 0 1\n")
                .find("graph.g2o:1: VERTEX_SE3:QUAT needs 8 fields"),
            std::string::npos);
  EXPECT_NE(
      error_of("VERTEX_SE3:QUAT 0 0 0 zero 0 0 0 1\n").find("graph.g2o:1: 'zero' is not a number"),
      std::string::npos);
  EXPECT_NE(error_of("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n")
                .find("graph.g2o:2: vertex id 0 appears twice"),
            std::string::npos);
  EXPECT_NE(error_of("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 7 1 0 0 0 0 0 1 " +
                     std::string(kIdentityInformation) + "\n")
                .find("graph.g2o:2: edge names vertex 7, which has no VERTEX line"),
            std::string::npos);
  EXPECT_NE(
      error_of("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n").find("graph.g2o:1: the quaternion has zero"),
      std::string::npos);
  EXPECT_NE(
      error_of("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n"
               "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 -1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n")
          .find("graph.g2o:3: constraint 0 -> 1: the information matrix has a negative eigenvalue"),
      std::string::npos);
  EXPECT_NE(error_of("# nothing\n").find("no VERTEX_SE3:QUAT line"), std::string::npos);
}

TEST(BackendG2o, MissingFileSaysSo) {
  try {
    read_g2o("/nonexistent/graph.g2o");
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("/nonexistent/graph.g2o: cannot open"),
              std::string::npos);
  }
}

}  // namespace
}  // namespace backend
}  // namespace covox

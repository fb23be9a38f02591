#include "planeslam/mapping/g2o_io.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <random>
#include <sstream>

#include "planeslam/datasets/errors.hpp"
#include "test_support.hpp"

namespace planeslam::mapping {
namespace {

void ExpectSameGraph(const PoseGraph& a, const PoseGraph& b) {
  ASSERT_EQ(a.nodes().size(), b.nodes().size());
  ASSERT_EQ(a.edges().size(), b.edges().size());
  for (std::size_t i = 0; i < a.nodes().size(); ++i) {
    const auto& x = a.nodes()[i];
    const auto& y = b.nodes()[i];
    EXPECT_EQ(x.id, y.id);
    EXPECT_EQ(x.position, y.position) << "vertex " << x.id;
    EXPECT_EQ(x.rotation.coeffs(), y.rotation.coeffs()) << "vertex " << x.id;
    EXPECT_EQ(x.fixed, y.fixed);
  }
  for (std::size_t i = 0; i < a.edges().size(); ++i) {
    const auto& x = a.edges()[i];
    const auto& y = b.edges()[i];
    EXPECT_EQ(x.from, y.from);
    EXPECT_EQ(x.to, y.to);
    EXPECT_EQ(x.translation, y.translation) << "edge " << i;
    EXPECT_EQ(x.rotation.coeffs(), y.rotation.coeffs()) << "edge " << i;
    EXPECT_EQ(x.information, y.information) << "edge " << i;
    EXPECT_EQ(x.kind, y.kind);
  }
}

std::vector<double> Numbers(const std::string& line) {
  std::istringstream in(line);
  std::string token;
  in >> token;  // tag
  std::vector<double> out;
  while (in >> token) out.push_back(std::strtod(token.c_str(), nullptr));
  return out;
}

PoseGraph RandomGraph(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-3.0, 3.0);
  PoseGraph graph;
  for (int i = 0; i < 8; ++i) {
    PoseGraphNode node;
    node.id = 100 + i;
    node.position = Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
    node.rotation =
        Eigen::Quaterniond(Eigen::Vector4d(uniform(rng), uniform(rng), uniform(rng), uniform(rng)))
            .normalized();
    node.fixed = i == 3;
    graph.AddNode(node);
  }
  for (int i = 0; i < 10; ++i) {
    PoseGraphEdge edge;
    edge.from = 100 + i % 8;
    edge.to = 100 + (i * 3 + 1) % 8;
    if (edge.to == edge.from) edge.to = 100 + (i + 1) % 8;
    edge.kind = edge.to == edge.from + 1 ? EdgeKind::kOdometry : EdgeKind::kLoopClosure;
    edge.translation = Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng)) / 7.0;
    edge.rotation =
        Eigen::Quaterniond(Eigen::Vector4d(uniform(rng), uniform(rng), uniform(rng), uniform(rng)))
            .normalized();
    Matrix6d A;
    for (int k = 0; k < 36; ++k) A(k) = uniform(rng) / 3.0;
    edge.information = A * A.transpose() + Matrix6d::Identity() * 0.1;
    graph.AddEdge(edge);
  }
  return graph;
}

TEST(G2oIo, GeneratedGraphRoundTripsExactly) {
  const PoseGraph graph = RandomGraph(1);
  const std::string text = FormatG2o(graph);
  std::istringstream in(text);
  const PoseGraph back = ParseG2o(in, "generated");
  ExpectSameGraph(graph, back);
  EXPECT_EQ(FormatG2o(back), text);
  EXPECT_NE(text.find("FIX 103\n"), std::string::npos);

  const auto path = test::ScratchDir() / "graph.g2o";
  WriteG2o(graph, path.string());
  ExpectSameGraph(graph, ReadG2o(path.string()));
}

TEST(G2oIo, ParkingGarageRoundTripsExactly) {
  PLANESLAM_REQUIRE_DATA();
  const auto path = test::DataDir() / "pose_graphs" / "parking-garage.g2o";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not found";
  const PoseGraph graph = ReadG2o(path.string());
  EXPECT_EQ(graph.nodes().size(), 1661u);
  EXPECT_EQ(graph.edges().size(), 6275u);
  EXPECT_GT(graph.NumLoopClosures(), 0u);

  const std::string text = FormatG2o(graph);
  std::istringstream in(text);
  const PoseGraph back = ParseG2o(in, "export");
  ExpectSameGraph(graph, back);
  EXPECT_EQ(FormatG2o(back), text);

  // Every number of the exported text equals the file's (same line order: vertices, then edges).
  std::ifstream file(path);
  std::istringstream exported(text);
  std::string original_line, exported_line;
  long line = 0;
  while (std::getline(file, original_line)) {
    ++line;
    ASSERT_TRUE(std::getline(exported, exported_line)) << "line " << line;
    ASSERT_EQ(Numbers(original_line), Numbers(exported_line)) << "line " << line;
  }
  EXPECT_FALSE(std::getline(exported, exported_line));
}

TEST(G2oIo, InformationConventionPreservesTheCost) {
  // g2o's chi2 of a small rotation error uses e = vec(dq) (half angle); ours uses 2 vec(dq).
  Matrix6d A = Matrix6d::Random();
  const Matrix6d g2o_information = A * A.transpose() + Matrix6d::Identity();
  const Matrix6d ours = InformationFromG2o(g2o_information);
  const Eigen::Matrix3d tt = g2o_information.topLeftCorner(3, 3);
  const Eigen::Matrix3d rr = g2o_information.bottomRightCorner(3, 3) / 4.0;
  const Eigen::Matrix3d tr = g2o_information.topRightCorner(3, 3) / 2.0;
  EXPECT_EQ(Eigen::Matrix3d(ours.topLeftCorner(3, 3)), tt);
  EXPECT_EQ(Eigen::Matrix3d(ours.bottomRightCorner(3, 3)), rr);
  EXPECT_EQ(Eigen::Matrix3d(ours.topRightCorner(3, 3)), tr);
  EXPECT_EQ(InformationToG2o(ours), g2o_information);
  const Eigen::Quaterniond dq(Eigen::AngleAxisd(0.01, Eigen::Vector3d(1, 2, -1).normalized()));
  Vector6d e_g2o, e_ours;
  e_g2o << 0.1, -0.2, 0.05, dq.vec();
  e_ours << 0.1, -0.2, 0.05, 2.0 * dq.vec();
  EXPECT_NEAR(e_ours.dot(ours * e_ours), e_g2o.dot(g2o_information * e_g2o), 1e-12);
}

std::string ParseError(const std::string& text) {
  std::istringstream in(text);
  try {
    ParseG2o(in, "bad.g2o");
  } catch (const IoError& e) {
    return e.what();
  }
  return "";
}

const char* kVertex0 = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n";
const char* kVertex1 = "VERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n";
const std::string kInfo = " 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 4 0 0 4 0 4";

TEST(G2oIo, MalformedLinesNameFileLineAndReason) {
  const std::string v = std::string(kVertex0) + kVertex1;
  EXPECT_EQ(ParseError(v + "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1" + kInfo + "\n"), "");
  EXPECT_EQ(ParseError("VERTEX_SE3:QUAT 0 0 0 0 0 0 1\n"),
            "bad.g2o:1: VERTEX_SE3:QUAT expects 8 values, got 7");
  EXPECT_EQ(ParseError(std::string("# comment\n\n") + "VERTEX_SE3:QUAT 0 0 x 0 0 0 0 1\n"),
            "bad.g2o:3: expected a number, got 'x'");
  EXPECT_EQ(ParseError("VERTEX_SE3:QUAT 0 0 1e999 0 0 0 0 1\n"),
            "bad.g2o:1: non-finite value '1e999'");
  EXPECT_EQ(ParseError("VERTEX_SE3:QUAT 0 0 nan 0 0 0 0 1\n"), "bad.g2o:1: non-finite value 'nan'");
  EXPECT_EQ(ParseError("VERTEX_SE3:QUAT 0.5 0 0 0 0 0 0 1\n"),
            "bad.g2o:1: expected an integer id, got '0.5'");
  EXPECT_EQ(ParseError("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n"),
            "bad.g2o:1: quaternion is not unit (norm 0)");
  EXPECT_EQ(ParseError(v + kVertex0), "bad.g2o:3: duplicate vertex id 0");
  EXPECT_EQ(ParseError(v + "EDGE_SE3:QUAT 0 7 1 0 0 0 0 0 1" + kInfo + "\n"),
            "bad.g2o:3: edge refers to unknown vertex id 7");
  EXPECT_EQ(ParseError(v + "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1" + kInfo + " 5\n"),
            "bad.g2o:3: EDGE_SE3:QUAT expects 30 values, got 31");
  EXPECT_EQ(ParseError(v + "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 4 0 0 "
                           "4 0 -4\n"),
            "bad.g2o:3: information matrix is not positive definite");
  EXPECT_EQ(ParseError(v + "EDGE_SE3:QUAT 1 1 1 0 0 0 0 0 1" + kInfo + "\n"),
            "bad.g2o:3: edge connects vertex 1 to itself");
  EXPECT_EQ(ParseError(v + "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"),
            "bad.g2o:3: unknown tag 'EDGE_SE2' (supported: VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX)");
  EXPECT_EQ(ParseError(v + "FIX 9\n"), "bad.g2o:3: FIX refers to unknown vertex id 9");
  EXPECT_EQ(ParseError(v + "FIX\n"), "bad.g2o:3: FIX expects at least one vertex id");
  EXPECT_EQ(ParseError(""), "");  // an empty file is an empty graph
}

TEST(G2oIo, FixAndOrderIndependence) {
  // Edges and FIX may come before the vertices they name.
  std::istringstream in("FIX 1\nEDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1" + kInfo + "\n" + kVertex0 +
                        kVertex1);
  const PoseGraph graph = ParseG2o(in, "order.g2o");
  EXPECT_FALSE(graph.node(0).fixed);
  EXPECT_TRUE(graph.node(1).fixed);
  ASSERT_EQ(graph.edges().size(), 1u);
  EXPECT_EQ(graph.edges()[0].kind, EdgeKind::kOdometry);
  // The file's rotation information 4 is 1 in our convention.
  EXPECT_EQ(graph.edges()[0].information(3, 3), 1.0);
}

TEST(G2oIo, MissingFileIsAnIoError) { EXPECT_THROW(ReadG2o("/nonexistent/graph.g2o"), IoError); }

}  // namespace
}  // namespace planeslam::mapping

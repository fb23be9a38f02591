// `planeslam graph optimize` end to end: the shared parking-garage benchmark converges to Ceres'
// own figures, the written graph reads back, and a small graph optimises to its loop's consensus.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

#include "cli_support.hpp"
#include "planeslam/mapping/g2o_io.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

TEST(GraphCli, ParkingGarageConvergesToCeresFigures) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = ScratchDir();
  const std::string in = (DataDir() / "pose_graphs/parking-garage.g2o").string();
  // As Ceres' example: the file's information as given, no robust loss.
  const CliResult r = RunCli("graph optimize " + in +
                                 " --raw-information --set pose_graph.loop_closure_loss=none --out " +
                                 (dir / "opt.g2o").string() + " --json " +
                                 (dir / "opt.json").string(),
                             dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(Slurp(dir / "opt.json"));
  EXPECT_EQ(j["vertices"].get<int>(), 1661);
  EXPECT_EQ(j["edges"].get<int>(), 6275);
  EXPECT_TRUE(j["converged"].get<bool>());
  // Ceres' examples/slam/pose_graph_3d on this file: initial 8.362723e+03, final 6.341883e-01.
  EXPECT_NEAR(j["initial_cost"].get<double>(), 8.362723e+03, 1e-5 * 8.362723e+03);
  EXPECT_NEAR(j["final_cost"].get<double>(), 6.341883e-01, 1e-4 * 6.341883e-01);
  const mapping::PoseGraph graph = mapping::ReadG2o((dir / "opt.g2o").string());
  EXPECT_EQ(graph.nodes().size(), 1661u);
  EXPECT_EQ(graph.edges().size(), 6275u);
}

TEST(GraphCli, SmallLoopReadsBackOptimised) {
  const fs::path dir = ScratchDir();
  const std::string info = " 100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400\n";
  // A square whose vertices were dead-reckoned with a 10 cm error on the last side.
  const std::string in = WriteText(dir, "square.g2o",
                                   "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n"
                                   "VERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n"
                                   "VERTEX_SE3:QUAT 2 1 1 0 0 0 0 1\n"
                                   "VERTEX_SE3:QUAT 3 0.1 1 0 0 0 0 1\n"
                                   "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1" + info +
                                   "EDGE_SE3:QUAT 1 2 0 1 0 0 0 0 1" + info +
                                   "EDGE_SE3:QUAT 2 3 -1 0 0 0 0 0 1" + info +
                                   "EDGE_SE3:QUAT 3 0 0 -1 0 0 0 0 1" + info);
  const CliResult r = RunCli("graph optimize " + in + " --out " + (dir / "out.g2o").string(), dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("converged       yes"), std::string::npos) << r.out;
  const mapping::PoseGraph graph = mapping::ReadG2o((dir / "out.g2o").string());
  // The measurements are mutually consistent: the optimum is the exact unit square.
  EXPECT_NEAR(graph.node(3).T_world_node().translation().x(), 0.0, 1e-6);
  EXPECT_NEAR(graph.node(3).T_world_node().translation().y(), 1.0, 1e-6);
}

}  // namespace
}  // namespace planeslam::test

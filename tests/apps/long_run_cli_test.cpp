// Loop closures as hypotheses, end to end: wrong closures injected into the built-in room are
// rejected or retracted and leave the trajectory as it was; on the aliasing ring (eight identical
// segments) no false closure is accepted; and a two-lap room stays in one piece. Shortened
// runs; `planeslam bench long-run` runs the full ones.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "cli_support.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

nlohmann::json RunAndSummarise(const std::string& args, const fs::path& dir) {
  const fs::path out = dir / "out";
  const CliResult r =
      RunCli("run -q --set octomap.enabled=false " + args + " --out " + out.string(), dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return nlohmann::json::parse(Slurp(out / "summary.json"));
}

/// The run's trajectory_tum.txt against `truth`, SE(3)-aligned on the first 300 pairs.
datasets::ApeResult ApeAlignedOnFirst300(const datasets::Trajectory& truth, const fs::path& out) {
  const datasets::Trajectory estimate =
      datasets::ReadTumTrajectory((out / "trajectory_tum.txt").string());
  datasets::ApeOptions options;
  options.alignment.align = true;
  options.alignment.n_to_align = 300;
  return datasets::EvaluateApe(truth, estimate, options);
}

std::size_t CountLines(const std::string& text) {
  std::size_t n = 0;
  for (char c : text) n += c == '\n';
  return n;
}

TEST(LongRunCli, InjectedFalseClosuresAreNotKept) {
  // A family of draws (three seeds of 50 injected closures each; `bench long-run` and
  // docs/RESULTS.md have five), failure budget 0: no injected closure may stay accepted, and the
  // trajectory stays within 0.2 cm of the clean run (0.52 cm).
  for (int seed = 1; seed <= 3; ++seed) {
    SCOPED_TRACE("inject_seed " + std::to_string(seed));
    const fs::path dir = ScratchDir() / std::to_string(seed);
    fs::create_directories(dir);
    const nlohmann::json summary = RunAndSummarise(
        "--set slam.inject_false_closures=50 --set slam.inject_seed=" + std::to_string(seed), dir);
    const nlohmann::json& closures = summary["closures"];
    // A closure planned for a frame after the last keyframe is never offered.
    EXPECT_GE(closures["injected"].get<int>(), 45);
    EXPECT_EQ(closures["injected_accepted"].get<int>(), 0);
    EXPECT_EQ(closures["ground_truth"]["false_accepted"].get<int>(), 0);
    EXPECT_GT(closures["accepted"].get<int>(), 20);  // the room's true closures still close it
    EXPECT_LT(summary["metrics"]["ate"]["rmse"].get<double>(), 0.0072);
    // One closures.csv row per hypothesis, each with a status and a reason, and what verified
    // it: every injected closure says so.
    const std::string csv = Slurp(dir / "out" / "closures.csv");
    EXPECT_EQ(CountLines(csv), closures["hypotheses"].get<std::size_t>() + 1);
    EXPECT_NE(csv.find(",map_vouched,verified_by"), std::string::npos);
    std::size_t injected_rows = 0;
    for (std::size_t at = csv.find(",injected"); at != std::string::npos;
         at = csv.find(",injected", at + 1)) {
      ++injected_rows;
    }
    EXPECT_EQ(injected_rows, closures["injected"].get<std::size_t>() + 1);  // + the header's
  }
}

TEST(LongRunCli, OtherNoiseSeedsStayOnTheTruth) {
  // A family of rooms (the noise seed also moves the clutter), failure budget 0: aligned on its
  // first 300 frames, no frame of the first 430 strays by more than 4 cm. With a held turn
  // continued along a least-squares trend, one wrong frame before the turn was held (seed 2,
  // frame 402) bent the roll by 22 deg over the next 16 frames.
  for (int seed = 2; seed <= 4; ++seed) {
    SCOPED_TRACE("simulation.seed " + std::to_string(seed));
    const fs::path dir = ScratchDir() / std::to_string(seed);
    fs::create_directories(dir);
    RunAndSummarise("--set run.max_frames=430 --set simulation.seed=" + std::to_string(seed), dir);
    const datasets::ApeResult ape = ApeAlignedOnFirst300(
        datasets::ReadTumTrajectory((dir / "out" / "ground_truth_tum.txt").string()), dir / "out");
    ASSERT_TRUE(ape.ok) << ape.message;
    EXPECT_EQ(ape.stats.count, 430u);
    EXPECT_LT(ape.stats.max, 0.04);
  }
}

TEST(LongRunCli, AliasingRingAcceptsNoFalseClosure) {
  const fs::path dir = ScratchDir();
  const nlohmann::json summary = RunAndSummarise("--scene ring --set simulation.laps=1.15", dir);
  const nlohmann::json& closures = summary["closures"];
  EXPECT_GT(closures["accepted"].get<int>(), 0);
  EXPECT_EQ(closures["ground_truth"]["false_accepted"].get<int>(), 0);
  // The map holds each surface once: no more planes than the scene has.
  datasets::SyntheticConfig ring = datasets::SyntheticConfig::ForScene(datasets::SceneKind::kRing);
  EXPECT_LE(summary["map_planes"].get<std::size_t>(),
            datasets::SyntheticSequence(ring).scene().planes.size());
}

TEST(LongRunCli, TwoLapsStayInOnePiece) {
  const fs::path dir = ScratchDir();
  const nlohmann::json summary = RunAndSummarise("--set simulation.laps=2", dir);
  EXPECT_EQ(summary["closures"]["ground_truth"]["false_accepted"].get<int>(), 0);
  EXPECT_GT(summary["back_end"]["local_optimizations"].get<int>(), 0);
  // Aligned on its first 300 frames, the whole estimate stays on the truth: a map split in two
  // would show as a jump of tens of centimetres.
  datasets::SyntheticConfig room = datasets::SyntheticConfig::ForScene(datasets::SceneKind::kRoom);
  room.trajectory.laps = 2.0;
  const datasets::SyntheticSequence sequence(room);
  // Each surface once, lap after lap: no more map planes than the scene has planes (facets of
  // its curved objects, seldom detected where keyframes looked at them, are culled).
  EXPECT_GT(summary["back_end"]["map_planes_culled"].get<int>(), 0);
  EXPECT_LE(summary["map_planes"].get<std::size_t>(), sequence.scene().planes.size());
  const datasets::ApeResult ape =
      ApeAlignedOnFirst300(sequence.GroundTruthTrajectory(), dir / "out");
  ASSERT_TRUE(ape.ok) << ape.message;
  EXPECT_LT(ape.stats.max, 0.05);
}

}  // namespace
}  // namespace planeslam::test

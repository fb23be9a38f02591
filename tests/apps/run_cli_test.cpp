// `planeslam run` end to end on the built-in synthetic room: every output is written and reads
// back with the project's own readers, and Ctrl-C (SIGINT) leaves complete outputs for the frames
// done (exit 130, no temporary files).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fcntl.h>
#include <filesystem>
#include <string>
#include <thread>

#include "cli_support.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "planeslam/mapping/g2o_io.hpp"
#include "planeslam/mapping/occupancy_map.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

std::size_t CountLines(const std::string& text) {
  std::size_t n = 0;
  for (char c : text) n += c == '\n';
  return n;
}

bool HasTemporaryFiles(const fs::path& dir) {
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.path().filename().string().find(".tmp.") != std::string::npos) return true;
  }
  return false;
}

/// The outputs of a run over `frames` frames are all there and consistent with each other.
void ExpectCompleteOutputs(const fs::path& out, std::size_t frames, bool octomap) {
  const auto summary = nlohmann::json::parse(Slurp(out / "summary.json"));
  EXPECT_EQ(summary["frames"].get<std::size_t>(), frames);
  const datasets::Trajectory trajectory =
      datasets::ReadTumTrajectory((out / "trajectory_tum.txt").string());
  EXPECT_EQ(trajectory.size(), frames);
  // The TUM file opens in `planeslam eval` (against itself: every pose pairs, error 0).
  const std::string tum = (out / "trajectory_tum.txt").string();
  const CliResult eval = RunCli("eval ape " + tum + " " + tum, out);
  EXPECT_EQ(eval.exit_code, 0) << eval.err;
  EXPECT_NE(eval.out.find("pairs\t" + std::to_string(frames)), std::string::npos) << eval.out;
  EXPECT_NE(eval.out.find("rmse\t0.000000"), std::string::npos) << eval.out;
  // frames.csv: a header and one row per frame.
  EXPECT_EQ(CountLines(Slurp(out / "frames.csv")), frames + 1);
  const auto map = nlohmann::json::parse(Slurp(out / "plane_map.json"));
  EXPECT_EQ(map["format"].get<std::string>(), "planeslam-plane-map");
  ASSERT_FALSE(map["planes"].empty());
  for (const auto& plane : map["planes"]) {
    const auto& n = plane["normal"];
    const double norm = std::sqrt(n[0].get<double>() * n[0].get<double>() +
                                  n[1].get<double>() * n[1].get<double>() +
                                  n[2].get<double>() * n[2].get<double>());
    EXPECT_NEAR(norm, 1.0, 1e-6);
    // Planes seen in too few keyframes for a polygon carry area 0 (plane map's convention).
    EXPECT_GE(plane["area"].get<double>(), 0.0);
  }
  const mapping::PoseGraph graph = mapping::ReadG2o((out / "pose_graph.g2o").string());
  EXPECT_EQ(graph.nodes().size(), summary["keyframes"].get<std::size_t>());
  EXPECT_EQ(graph.edges().size(), summary["keyframes"].get<std::size_t>() - 1 +
                                      summary["loop_closures"].get<std::size_t>());
  if (octomap && mapping::OccupancyMapBuilder::available()) {
    const auto tree = mapping::OccupancyMapBuilder::Load((out / "octomap.bt").string());
    EXPECT_GT(tree.Stats().occupied_leaves + tree.Stats().free_leaves, 0u);
  }
  EXPECT_FALSE(HasTemporaryFiles(out));
}

TEST(RunCli, SyntheticRoomWritesOutputsThatLoad) {
  const fs::path dir = ScratchDir();
  const fs::path out = dir / "out";
  const CliResult r = RunCli("run -q --set run.max_frames=40 --out " + out.string(), dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ExpectCompleteOutputs(out, 40, /*octomap=*/true);
  // With ground truth the run scores itself: over the first 40 frames of the room (six or more
  // planes in view, well-conditioned) plane tracking stays within a centimetre.
  const auto metrics = nlohmann::json::parse(Slurp(out / "metrics.json"));
  EXPECT_EQ(metrics["ate"]["pairs"].get<std::size_t>(), 40u);
  EXPECT_LT(metrics["ate"]["rmse"].get<double>(), 0.01);
}

TEST(RunCli, SigintWritesCompleteOutputsForFramesDone) {
  const fs::path dir = ScratchDir();
  const fs::path out = dir / "out";
  const fs::path stdout_path = dir / "stdout.txt";
  const std::string out_arg = out.string();
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int fd = open(stdout_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) dup2(fd, STDOUT_FILENO);
    const int null_fd = open("/dev/null", O_RDWR);
    if (null_fd >= 0) {
      dup2(null_fd, STDIN_FILENO);
      dup2(null_fd, STDERR_FILENO);
    }
    // 15 laps of the room (5655 frames): a minute or more at any speed, so the interrupt below
    // always lands in the middle of the run.
    execl(PLANESLAM_BIN, PLANESLAM_BIN, "run", "-q", "--set", "simulation.laps=15", "--set",
          "octomap.enabled=false", "--out", out_arg.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  // Long enough for the first frames on a loaded machine, far shorter than the run.
  std::this_thread::sleep_for(std::chrono::seconds(4));
  ASSERT_EQ(kill(pid, SIGINT), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  const std::string text = Slurp(stdout_path);
  ASSERT_EQ(WEXITSTATUS(status), 130) << text;
  EXPECT_NE(text.find("INTERRUPTED"), std::string::npos) << text;
  const auto summary = nlohmann::json::parse(Slurp(out / "summary.json"));
  EXPECT_TRUE(summary["interrupted"].get<bool>());
  const std::size_t frames = summary["frames"].get<std::size_t>();
  EXPECT_GT(frames, 0u);
  EXPECT_LT(frames, 5655u);
  ExpectCompleteOutputs(out, frames, /*octomap=*/false);
}

}  // namespace
}  // namespace planeslam::test

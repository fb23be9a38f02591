// KITTI-layout sequences through the command line: a simulated street runs without -c (the kitti
// profile is recognised, giving the same outputs as with its config file), a bad scan inside a run is reported and skipped, `eval kitti` prints
// the devkit's segment errors, and `run` / `bench odometry` report them for KITTI ground truth.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "cli_support.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(KittiCli, SimulatedStreetRunsWithoutConfigAndSkipsABadScan) {
  const fs::path dir = ScratchDir();
  const fs::path street = dir / "street";
  const CliResult sim = RunCli("simulate street -q --frames 5 --out " + street.string(), dir);
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  for (const char* f : {"velodyne/000004.bin", "labels/000004.label", "poses.txt", "times.txt",
                        "calib.txt", "planes.json", "config.yaml"}) {
    EXPECT_TRUE(fs::is_regular_file(street / f)) << f;
  }
  const CliResult run = RunCli("run -q " + street.string() + " --out " + (dir / "run").string() +
                                   " --set octomap.enabled=false",
                               dir);
  ASSERT_EQ(run.exit_code, app::kExitSuccess) << run.err;
  EXPECT_TRUE(Contains(run.err, "--sensor kitti")) << run.err;
  EXPECT_EQ(datasets::ReadTumTrajectory((dir / "run" / "trajectory_tum.txt").string()).size(), 5u);
  // The recognised profile is the configs a user would give: the same trajectory and map.
  const CliResult with_configs =
      RunCli("run -q " + street.string() + " --sensor none -c " + PLANESLAM_SOURCE_DIR +
                 "/config/kitti_hdl64.yaml --out " + (dir / "run_c").string() +
                 " --set octomap.enabled=false",
             dir);
  ASSERT_EQ(with_configs.exit_code, app::kExitSuccess) << with_configs.err;
  for (const char* f : {"trajectory_tum.txt", "plane_map.json"}) {
    EXPECT_EQ(Slurp(dir / "run" / f), Slurp(dir / "run_c" / f)) << f;
  }

  // Scan 2 cut in the middle of a point: left out, the run completes with exit code 5.
  const fs::path bad = street / "velodyne" / "000002.bin";
  const std::string bytes = Slurp(bad);
  { std::ofstream(bad, std::ios::binary) << bytes.substr(0, bytes.size() / 2 + 5); }
  const CliResult skip = RunCli("run -q " + street.string() + " --out " + (dir / "skip").string() +
                                    " --set octomap.enabled=false",
                                dir);
  ASSERT_EQ(skip.exit_code, app::kExitSkippedFrames) << skip.err;
  EXPECT_TRUE(Contains(skip.err, "frame 2 skipped: " + bad.string() + ": truncated")) << skip.err;
  const auto summary = nlohmann::json::parse(Slurp(dir / "skip" / "summary.json"));
  EXPECT_EQ(summary["skipped_frames"].get<int>(), 1);
}

/// `planeslam run --scene street` (no folder) gets the profile its `simulate` output would get, so
/// the built-in LiDAR scene runs as configured; --sensor none and the depth-camera scenes keep
/// the defaults.
TEST(KittiCli, BuiltInStreetGetsTheLidarProfile) {
  const fs::path dir = ScratchDir();
  const std::string common =
      " -q --no-report --set octomap.enabled=false --set simulation.frames=3";
  const CliResult street =
      RunCli("run --scene street" + common + " --out " + (dir / "street").string(), dir);
  ASSERT_EQ(street.exit_code, app::kExitSuccess) << street.err;
  EXPECT_TRUE(Contains(street.err, "built-in scene street, simulated LiDAR")) << street.err;
  EXPECT_TRUE(Contains(street.err, "--sensor kitti")) << street.err;
  const std::string effective = Slurp(dir / "street" / "config.yaml");
  EXPECT_TRUE(Contains(effective, "plane_landmarks: false")) << effective;
  EXPECT_TRUE(Contains(effective, "keyframe_translation: 1 ")) << effective;

  const CliResult none = RunCli(
      "run --scene street --sensor none" + common + " --out " + (dir / "none").string(), dir);
  ASSERT_EQ(none.exit_code, app::kExitSuccess) << none.err;
  EXPECT_TRUE(Contains(none.err, "no sensor profile (--sensor none)")) << none.err;
  EXPECT_TRUE(Contains(Slurp(dir / "none" / "config.yaml"), "plane_landmarks: true"));

  const CliResult room =
      RunCli("run --scene room" + common + " --out " + (dir / "room").string(), dir);
  ASSERT_EQ(room.exit_code, app::kExitSuccess) << room.err;
  EXPECT_FALSE(Contains(room.err, "--sensor")) << room.err;
  EXPECT_TRUE(Contains(Slurp(dir / "room" / "config.yaml"), "plane_landmarks: true"));
}

/// Reference: 401 poses 1 m apart on a line; estimate: 1.5 % longer steps. Every segment's error
/// is 0.015 (L + 1) / L (the devkit's last frame lies one step beyond L).
TEST(KittiCli, EvalKittiPrintsDevkitSegmentErrors) {
  const fs::path dir = ScratchDir();
  std::string ref, est, tum;
  for (int i = 0; i <= 400; ++i) {
    ref += "1 0 0 " + std::to_string(i) + " 0 1 0 0 0 0 1 0\n";
    est += "1 0 0 " + std::to_string(1.015 * i) + " 0 1 0 0 0 0 1 0\n";
    tum += std::to_string(0.1 * i) + " " + std::to_string(1.015 * i) + " 0 0 0 0 0 1\n";
  }
  WriteText(dir, "ref.txt", ref);
  WriteText(dir, "est.txt", est);
  WriteText(dir, "est_tum.txt", tum);
  std::string times;
  for (int i = 0; i <= 400; ++i) times += std::to_string(0.1 * i) + "\n";
  WriteText(dir, "times.txt", times);
  double sum = 0.0;
  int count = 0;
  for (int L = 100; L <= 300; L += 100) {
    const int n = (400 - L - 1) / 10 + 1;
    sum += n * 0.015 * (L + 1.0) / L;
    count += n;
  }
  char expected[64];
  std::snprintf(expected, sizeof(expected), "translation  %.4f %%", 100.0 * sum / count);
  const CliResult r = RunCli("eval kitti " + (dir / "ref.txt").string() + " " +
                                 (dir / "est.txt").string() + " --json " +
                                 (dir / "k.json").string() + " --plot " + (dir / "plots").string(),
                             dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, expected)) << r.out;
  EXPECT_TRUE(Contains(r.out, "rotation     0.0000 deg/100m")) << r.out;
  EXPECT_TRUE(Contains(r.out, std::to_string(count) + " segments")) << r.out;
  const auto j = nlohmann::json::parse(Slurp(dir / "k.json"));
  EXPECT_NEAR(j["translation_percent"].get<double>(), 100.0 * sum / count, 1e-9);
  EXPECT_EQ(j["per_length"].size(), 3u);
  EXPECT_TRUE(fs::is_regular_file(dir / "plots" / "kitti_translation.svg"));
  // The estimate as a TUM file, the reference's stamps from its times file: the same figures.
  const CliResult t = RunCli("eval kitti " + (dir / "ref.txt").string() + " " +
                                 (dir / "est_tum.txt").string() + " --ref-times " +
                                 (dir / "times.txt").string(),
                             dir);
  ASSERT_EQ(t.exit_code, 0) << t.err;
  EXPECT_TRUE(Contains(t.out, expected)) << t.out;
}

/// A street driven with one scan every 10 m (1 Hz) over 110 m: run and bench odometry print and
/// store the segment errors of the 100 m segments.
TEST(KittiCli, RunAndBenchReportSegmentErrors) {
  const fs::path dir = ScratchDir();
  const fs::path street = dir / "street";
  const CliResult sim = RunCli("simulate street -q --frames 12 --set simulation.rate=1 --out " +
                                   street.string(),
                               dir);
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  const CliResult run = RunCli("run -q " + street.string() + " --out " + (dir / "run").string() +
                                   " --set octomap.enabled=false",
                               dir);
  ASSERT_EQ(run.exit_code, app::kExitSuccess) << run.err;
  EXPECT_TRUE(Contains(run.out, "KITTI segment errors: translation ")) << run.out;
  const auto metrics = nlohmann::json::parse(Slurp(dir / "run" / "metrics.json"));
  ASSERT_TRUE(metrics.contains("kitti")) << metrics.dump();
  EXPECT_GT(metrics["kitti"]["segments"].get<int>(), 0);
  EXPECT_EQ(metrics["kitti"]["per_length"][0]["length_m"].get<double>(), 100.0);

  const CliResult bench = RunCli("bench odometry -q " + street.string() + " --json " +
                                     (dir / "bench.json").string() + " --gicp-voxel 1.0",
                                 dir);
  ASSERT_EQ(bench.exit_code, 0) << bench.err;
  EXPECT_TRUE(Contains(bench.out, "KITTI segment errors (devkit")) << bench.out;
  const auto j = nlohmann::json::parse(Slurp(dir / "bench.json"));
  ASSERT_FALSE(j.empty());
  EXPECT_TRUE(j[0].contains("kitti")) << j.dump();
}

}  // namespace
}  // namespace planeslam::test

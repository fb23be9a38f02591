// Same input and config give byte-identical outputs. The only documented exceptions are
// summary.json, which records wall-clock times per stage, and report.html, which shows them.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

TEST(Determinism, RunTwiceGivesIdenticalFiles) {
  const fs::path dir = ScratchDir();
  const std::string args = "run -q --set run.max_frames=45 --out ";
  for (const char* name : {"a", "b"}) {
    const CliResult r = RunCli(args + (dir / name).string(), dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  int compared = 0;
  for (const auto& entry : fs::recursive_directory_iterator(dir / "a")) {
    const fs::path name = entry.path().filename();
    if (!entry.is_regular_file() || name == "summary.json" || name == "report.html") continue;
    const fs::path other = dir / "b" / fs::relative(entry.path(), dir / "a");
    ASSERT_TRUE(fs::exists(other)) << other;
    EXPECT_TRUE(Slurp(entry.path()) == Slurp(other)) << "differs: " << entry.path().filename();
    ++compared;
  }
  EXPECT_GE(compared, 8);  // trajectories, plane map x3, g2o, config, frames.csv, metrics, plots
}

TEST(Determinism, SimulateTwiceGivesIdenticalFiles) {
  const fs::path dir = ScratchDir();
  for (const char* name : {"a", "b"}) {
    const CliResult r =
        RunCli("simulate rubble --frames 3 --out " + (dir / name).string(), dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  int compared = 0;
  for (const auto& entry : fs::recursive_directory_iterator(dir / "a")) {
    if (!entry.is_regular_file()) continue;
    const fs::path other = dir / "b" / fs::relative(entry.path(), dir / "a");
    EXPECT_TRUE(Slurp(entry.path()) == Slurp(other)) << "differs: " << entry.path().filename();
    ++compared;
  }
  EXPECT_GE(compared, 8);
}

}  // namespace
}  // namespace planeslam::test

// frames.csv says what constrained each frame of `planeslam run`, and summary.json counts the
// frames that took a direction from the motion prior: the synthetic corridor's planes leave its
// axis open, and that is never filled silently.
#include <algorithm>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream in(line);
  std::string field;
  while (std::getline(in, field, ',')) fields.push_back(field);
  if (!line.empty() && line.back() == ',') fields.push_back("");
  return fields;
}

struct SourceCounts {
  int rows = 0, with_prior = 0, with_points = 0;
};

/// Runs the first 12 corridor frames and checks frames.csv's constrained_by against its
/// weak_directions and the summary's count of frames that took a direction from the prior.
SourceCounts RunCorridor(const std::string& settings) {
  const fs::path dir = ScratchDir();
  const fs::path out = dir / "corridor";
  const CliResult run = RunCli(
      "run --scene corridor --set run.max_frames=12 --quiet " + settings + " --out " + out.string(),
      dir);
  SourceCounts counts;
  EXPECT_EQ(run.exit_code, 0) << run.err;
  std::stringstream csv(Slurp(out / "frames.csv"));
  std::string line;
  EXPECT_TRUE(std::getline(csv, line));
  const std::vector<std::string> header = SplitCsv(line);
  const auto column = [&header](const std::string& name) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  const std::size_t source = column("constrained_by"), weak_column = column("weak_directions");
  if (source >= header.size() || weak_column >= header.size()) {
    ADD_FAILURE() << "frames.csv header: " << line;
    return counts;
  }
  const std::set<std::string> allowed = {"planes",       "planes+points", "planes+prior",
                                         "planes+points+prior", "points", "points+prior",
                                         "prior"};
  while (std::getline(csv, line)) {
    const std::vector<std::string> f = SplitCsv(line);
    EXPECT_EQ(f.size(), header.size()) << line;
    if (f.size() != header.size()) continue;
    EXPECT_TRUE(allowed.count(f[source])) << line;
    // A frame with an open direction names what filled it; a fully constrained one says planes.
    if (std::stoi(f[weak_column]) == 0) {
      EXPECT_EQ(f[source], "planes") << line;
    }
    if (f[source].find("prior") != std::string::npos) ++counts.with_prior;
    if (f[source].find("points") != std::string::npos) ++counts.with_points;
    ++counts.rows;
  }
  const auto summary = nlohmann::json::parse(Slurp(out / "summary.json"));
  EXPECT_EQ(summary["prior_frames"].get<int>(), counts.with_prior);
  EXPECT_NE(run.out.find("frames with a direction from the prior " +
                         std::to_string(counts.with_prior)),
            std::string::npos)
      << run.out;
  return counts;
}

TEST(ConstraintSourceCli, FramesCsvFlagsWhatConstrainedEachFrame) {
  // The corridor's planes leave its axis open: the fused depth map fills it, and without the
  // depth map it is left to the prior, which frames.csv and the summary say.
  const SourceCounts filled = RunCorridor("");
  EXPECT_EQ(filled.rows, 12);
  EXPECT_GT(filled.with_points, 0);
  const SourceCounts held = RunCorridor("--set slam.depth_map_fill=false");
  EXPECT_EQ(held.rows, 12);
  EXPECT_GT(held.with_prior, 0);
  EXPECT_EQ(held.with_points, 0);
}

}  // namespace
}  // namespace planeslam::test

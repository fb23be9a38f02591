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

TEST(ConstraintSourceCli, FramesCsvFlagsWhatConstrainedEachFrame) {
  const fs::path dir = ScratchDir();
  const fs::path out = dir / "corridor";
  const CliResult run = RunCli(
      "run --scene corridor --set run.max_frames=12 --quiet --out " + out.string(), dir);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  std::stringstream csv(Slurp(out / "frames.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  const std::vector<std::string> header = SplitCsv(line);
  const auto column = [&header](const std::string& name) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  const std::size_t source = column("constrained_by"), weak_column = column("weak_directions");
  ASSERT_LT(source, header.size()) << line;
  ASSERT_LT(weak_column, header.size()) << line;
  const std::set<std::string> allowed = {"planes",       "planes+points", "planes+prior",
                                         "planes+points+prior", "points", "points+prior",
                                         "prior"};
  int rows = 0, with_prior = 0;
  while (std::getline(csv, line)) {
    const std::vector<std::string> f = SplitCsv(line);
    ASSERT_EQ(f.size(), header.size()) << line;
    EXPECT_TRUE(allowed.count(f[source])) << line;
    const int weak = std::stoi(f[weak_column]);
    // A frame with an open direction names what filled it; a fully constrained one says planes.
    if (weak == 0) EXPECT_EQ(f[source], "planes") << line;
    if (f[source].find("prior") != std::string::npos) ++with_prior;
    ++rows;
  }
  EXPECT_EQ(rows, 12);
  EXPECT_GT(with_prior, 0);  // the corridor's axis, left to the prior by the depth-image path
  const auto summary = nlohmann::json::parse(Slurp(out / "summary.json"));
  EXPECT_EQ(summary["prior_frames"].get<int>(), with_prior);
  EXPECT_NE(run.out.find("frames with a direction from the prior " + std::to_string(with_prior)),
            std::string::npos)
      << run.out;
}

}  // namespace
}  // namespace planeslam::test

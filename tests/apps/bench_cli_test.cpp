// Runs `planeslam bench detect` on one real frame and checks what it reports.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "bench_common.hpp"
#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;

TEST(BenchCli, DetectOneFrameWritesJsonPerMethod) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path frame = test::DataDir() / "tum_fr3_structure_notexture_far" / "depth" /
                         "1341836537.655691.png";
  if (!fs::exists(frame)) GTEST_SKIP() << frame << " not found";
  const fs::path dir = test::ScratchDir();
  const fs::path json = dir / "bench.json";
  const test::CliResult r = test::RunCli(
      "bench detect '" + frame.string() + "' --repeat 2 --json '" + json.string() + "' --quiet",
      dir);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const std::string& out = r.out;
  std::ifstream in(json);
  ASSERT_TRUE(in.good()) << "no JSON written; output:\n" << out;
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_TRUE(j.is_array());

  // One object per method (one frame), covering every method the binary knows.
  const std::vector<std::string> all = bench::AllMethods();
  ASSERT_EQ(j.size(), all.size());
  std::set<std::string> seen;
  for (const auto& rec : j) {
    for (const char* key : {"method", "frame", "median_ms", "min_ms", "planes", "times_ms",
                            "assigned_fraction", "valid_points"}) {
      ASSERT_TRUE(rec.contains(key)) << key << " missing in " << rec.dump();
    }
    seen.insert(rec["method"].get<std::string>());
    EXPECT_EQ(rec["frame"], "1341836537.655691");
    EXPECT_EQ(rec["times_ms"].size(), 2u);
    const double median = rec["median_ms"], min = rec["min_ms"];
    EXPECT_GT(min, 0.0);
    EXPECT_LE(min, median);
    // The median of two runs is their mean, so it cannot exceed the slower one.
    const double t0 = rec["times_ms"][0].get<double>(), t1 = rec["times_ms"][1].get<double>();
    EXPECT_LE(median, std::max(t0, t1) + 1e-9);
    // A TUM Kinect frame of walls and floor: every method finds planes and labels part of it.
    EXPECT_GE(rec["planes"].get<int>(), 1) << rec.dump();
    const double assigned = rec["assigned_fraction"];
    EXPECT_GT(assigned, 0.0);
    EXPECT_LE(assigned, 1.0);
    EXPECT_GT(rec["valid_points"].get<int>(), 100000);
    if (rec["method"] != "pcl_omps" && rec.contains("speedup_vs_pcl")) {
      EXPECT_GT(rec["speedup_vs_pcl"].get<double>(), 0.0);
    }
  }
  EXPECT_EQ(seen, std::set<std::string>(all.begin(), all.end()));
  // The summary names every method.
  for (const std::string& m : all) EXPECT_NE(out.find(m), std::string::npos) << out;
}

TEST(BenchCli, UnknownMethodIsAOneLineError) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path frame = test::DataDir() / "tum_fr3_structure_notexture_far" / "depth" /
                         "1341836537.655691.png";
  if (!fs::exists(frame)) GTEST_SKIP() << frame << " not found";
  const test::CliResult r = test::RunCli(
      "bench detect '" + frame.string() + "' --methods nosuch --repeat 1", test::ScratchDir());
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("unknown method 'nosuch'"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace planeslam::app

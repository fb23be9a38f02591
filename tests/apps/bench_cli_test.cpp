// Runs `planeslam bench detect` on one real frame and `planeslam bench odometry` on a short
// synthetic corridor, and checks what they report.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>

#include "bench_common.hpp"
#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;

TEST(BenchCli, DetectOneFrameWritesJsonPerMethod) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path frame =
      test::DataDir() / "tum_fr3_structure_notexture_far" / "depth" / "1341836537.655691.png";
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

TEST(BenchCli, SpeedRatioOverVgaFramesLeavesTheLaserScanOut) {
  // The detection speed targets are stated for 640 x 480 Kinect frames: the summary's last ratio
  // is the median over those only, the first over every frame.
  PLANESLAM_REQUIRE_DATA();
  const std::vector<std::string> all = bench::AllMethods();
  if (std::find(all.begin(), all.end(), "pcl_omps") == all.end()) {
    GTEST_SKIP() << "built without the PCL baselines";
  }
  const fs::path kinect =
      test::DataDir() / "tum_fr3_structure_notexture_far" / "depth" / "1341836537.655691.png";
  const fs::path scan = test::DataDir() / "laser_scans" / "scan000.pcd";
  if (!fs::exists(kinect) || !fs::exists(scan)) GTEST_SKIP() << kinect << " or " << scan;
  const fs::path dir = test::ScratchDir();
  const fs::path json = dir / "bench.json";
  const test::CliResult r = test::RunCli(
      "bench detect '" + kinect.string() + "' '" + scan.string() +
          "' --methods grid-fast,pcl_omps --repeat 1 --json '" + json.string() + "' --quiet",
      dir);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  std::ifstream in(json);
  ASSERT_TRUE(in.good()) << r.out;
  const nlohmann::json j = nlohmann::json::parse(in);
  double kinect_ratio = 0.0, scan_ratio = 0.0;
  for (const auto& rec : j) {
    if (rec["method"] != "grid-fast") continue;
    const double ratio = rec["speedup_vs_pcl"];
    if (rec["width"] == 640 && rec["height"] == 480) {
      kinect_ratio = ratio;
    } else {
      scan_ratio = ratio;
    }
  }
  ASSERT_GT(kinect_ratio, 0.0) << j.dump();
  ASSERT_GT(scan_ratio, 0.0) << j.dump();
  // The method's summary row: name, median ms, min ms, planes, assigned, then the three ratios.
  EXPECT_NE(r.out.find("x PCL (640x480)"), std::string::npos) << r.out;
  const std::size_t row = r.out.find("\ngrid-fast ");
  ASSERT_NE(row, std::string::npos) << r.out;
  std::istringstream fields(r.out.substr(row + 1, r.out.find('\n', row + 1) - row - 1));
  std::string name, median, min, planes, assigned, all_frames, of_medians, vga;
  fields >> name >> median >> min >> planes >> assigned >> all_frames >> of_medians >> vga;
  auto format = [](double ratio) {
    char text[32];
    std::snprintf(text, sizeof text, "%.1fx", ratio);
    return std::string(text);
  };
  EXPECT_EQ(vga, format(kinect_ratio)) << r.out;
  EXPECT_EQ(all_frames, format(0.5 * (kinect_ratio + scan_ratio))) << r.out;
}

TEST(BenchCli, UnknownMethodIsAOneLineError) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path frame =
      test::DataDir() / "tum_fr3_structure_notexture_far" / "depth" / "1341836537.655691.png";
  if (!fs::exists(frame)) GTEST_SKIP() << frame << " not found";
  const test::CliResult r = test::RunCli(
      "bench detect '" + frame.string() + "' --methods nosuch --repeat 1", test::ScratchDir());
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
  EXPECT_NE(r.err.find("unknown method 'nosuch'"), std::string::npos) << r.err;
}

TEST(BenchCli, OdometryOnACorridorReportsItsDegeneracyAndWritesBothTrajectories) {
  // A corridor's planes never fix the motion along it: every frame pair is degenerate along
  // world x, and the point-to-plane alignment fills it. (Without noise the front strips of the
  // pipes across the ceiling pass as planes facing the camera and do fix it; with the default
  // Kinect-like noise they do not.)
  const fs::path dir = test::ScratchDir();
  const std::string seq = (dir / "seq").string(), odo = (dir / "odo").string();
  const test::CliResult sim =
      test::RunCli("simulate corridor --out '" + seq + "' --frames 12 --quiet", dir);
  ASSERT_EQ(sim.exit_code, 0) << sim.out << sim.err;
  const test::CliResult r = test::RunCli(
      "bench odometry '" + seq + "' -c '" + PLANESLAM_SOURCE_DIR +
          "/config/detection_synthetic.yaml' --out '" + odo + "' --json '" + odo + ".json' --quiet",
      dir);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("degenerate on 11 of 11 frames (11 filled by point-to-plane alignment"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("undetermined translation axis| in the world (1.00, 0.00, 0.00)"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("drift from the first to the last frame"), std::string::npos) << r.out;
  std::ifstream in(odo + ".json");
  ASSERT_TRUE(in.good());
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_GE(j.size(), 1u);
  EXPECT_EQ(j[0]["method"], "planes(grid3)");
  EXPECT_EQ(j[0]["frames"], 12);
  EXPECT_EQ(j[0]["degenerate_frames"], 11);
  EXPECT_EQ(j[0]["filled_by_point_to_plane"], 11);
  EXPECT_EQ(j[0]["drift_world_m"].size(), 3u);
  for (const char* key : {"rpe_1_frame", "rpe_1_s"}) {
    ASSERT_TRUE(j[0].contains(key)) << j.dump();
    EXPECT_TRUE(std::isfinite(j[0][key]["trans_rmse_m"].get<double>())) << j.dump();
  }
  std::ifstream planes(dir / "odo" / "planes.txt");
  ASSERT_TRUE(planes.good());
  int lines = 0;
  for (std::string line; std::getline(planes, line);)
    lines += line.empty() || line[0] == '#' ? 0 : 1;
  EXPECT_EQ(lines, 12);
  // GICP's trajectory exists exactly when the PCL baselines are built in.
  EXPECT_EQ(fs::exists(dir / "odo" / "gicp.txt"), j.size() == 2u);
}

}  // namespace
}  // namespace planeslam::app

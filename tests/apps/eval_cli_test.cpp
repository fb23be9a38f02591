// `planeslam eval` end to end: the TUM tools' published numbers through the command line, evo's
// output layout on a hand-computed case, JSON and SVG outputs, and one-line errors with exit
// code 2.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "cli_support.hpp"
#include "svg_plot.hpp"
#include "test_support.hpp"

namespace planeslam::app {
namespace {

using test::CliResult;
using test::Slurp;
using test::WriteText;

CliResult RunEval(const std::string& args, const std::filesystem::path& dir) {
  return test::RunCli("eval " + args, dir);
}

std::string Data(const std::string& name) {
  return (test::DataDir() / "trajectories" / name).string();
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(EvalCli, TumAteReferenceValues) {
  PLANESLAM_REQUIRE_DATA();
  const auto dir = test::ScratchDir();
  CliResult r = RunEval("ape " + Data("freiburg1_xyz-groundtruth.txt") + " " +
                            Data("freiburg1_xyz-rgbdslam.txt") + " --tum",
                        dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out,
            "compared_pose_pairs 786 pairs\n"
            "absolute_translational_error.rmse 0.013473 m\n"
            "absolute_translational_error.mean 0.012029 m\n"
            "absolute_translational_error.median 0.011176 m\n"
            "absolute_translational_error.std 0.006068 m\n"
            "absolute_translational_error.min 0.000939 m\n"
            "absolute_translational_error.max 0.034727 m\n");
  r = RunEval("ape " + Data("fr2_desk_groundtruth.txt") + " " + Data("fr2_desk_ORB.txt") + " --tum",
              dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out,
            "compared_pose_pairs 2223 pairs\n"
            "absolute_translational_error.rmse 0.008144 m\n"
            "absolute_translational_error.mean 0.007514 m\n"
            "absolute_translational_error.median 0.007432 m\n"
            "absolute_translational_error.std 0.003140 m\n"
            "absolute_translational_error.min 0.000332 m\n"
            "absolute_translational_error.max 0.024329 m\n");
  // The repeated ground-truth stamp is reported, not silently dropped.
  EXPECT_TRUE(Contains(r.err, "fr2_desk_groundtruth.txt: 1 duplicate timestamp(s) (line 10863)"))
      << r.err;
}

TEST(EvalCli, TumRpeReferenceValuesAndJson) {
  PLANESLAM_REQUIRE_DATA();
  const auto dir = test::ScratchDir();
  const std::string json = (dir / "rpe.json").string();
  const CliResult r = RunEval("rpe " + Data("freiburg1_xyz-groundtruth.txt") + " " +
                                  Data("freiburg1_xyz-rgbdslam.txt") +
                                  " --tum --fixed-delta --delta 1 --delta-unit s --json " + json,
                              dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, "compared_pose_pairs 753 pairs\n")) << r.out;
  EXPECT_TRUE(Contains(r.out, "translational_error.rmse 0.021217 m\n")) << r.out;
  EXPECT_TRUE(Contains(r.out, "translational_error.mean 0.019524 m\n")) << r.out;
  EXPECT_TRUE(Contains(r.out, "rotational_error.rmse 0.934480 deg\n")) << r.out;
  EXPECT_TRUE(Contains(r.out, "rotational_error.mean 0.841472 deg\n")) << r.out;
  const nlohmann::json j = nlohmann::json::parse(Slurp(json));
  for (const char* key : {"rmse", "mean", "median", "std", "min", "max", "sse", "pairs"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["pairs"].get<int>(), 753);
  char rmse[32];
  std::snprintf(rmse, sizeof(rmse), "%.6f", j["rmse"].get<double>());
  EXPECT_STREQ(rmse, "0.021217");
  std::snprintf(rmse, sizeof(rmse), "%.6f", j["rotation_deg"]["rmse"].get<double>());
  EXPECT_STREQ(rmse, "0.934480");
}

TEST(EvalCli, EvoLayoutOnAHandComputedCase) {
  const auto dir = test::ScratchDir();
  // Estimate = reference shifted by (0.3, 0.4, 0): every APE is 0.5 m without alignment, 0 with.
  std::ostringstream ref, est;
  for (int i = 0; i < 10; ++i) {
    const double x = 0.1 * i, y = 0.05 * i * i;
    ref << 1.0 + 0.1 * i << " " << x << " " << y << " 0 0 0 0 1\n";
    est << 1.0 + 0.1 * i + 0.004 << " " << x + 0.3 << " " << y + 0.4 << " 0 0 0 0 1\n";
  }
  const std::string r_path = WriteText(dir, "ref.txt", ref.str());
  const std::string e_path = WriteText(dir, "est.txt", est.str());
  CliResult r = RunEval("ape " + r_path + " " + e_path, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out,
            "APE w.r.t. translation part (m)\n(not aligned)\n\n"
            "       max\t0.500000\n      mean\t0.500000\n    median\t0.500000\n"
            "       min\t0.500000\n      rmse\t0.500000\n       sse\t2.500000\n"
            "       std\t0.000000\n     pairs\t10\n");
  r = RunEval("ape " + r_path + " " + e_path + " -a", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, "(with SE(3) Umeyama alignment)\n")) << r.out;
  EXPECT_TRUE(Contains(r.out, "      rmse\t0.000000\n")) << r.out;
  // A 0.004 s stamp offset is outside --t-max-diff 0.001: nothing associates.
  r = RunEval("ape " + r_path + " " + e_path + " --t-max-diff 0.001", dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(
      r.err.rfind("planeslam: error: " + e_path + ": no timestamps within 0.001 s of " + r_path, 0),
      0u)
      << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1);
  // ... and --t-offset brings it back.
  r = RunEval("ape " + r_path + " " + e_path + " --t-max-diff 0.001 --t-offset -0.004", dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, "     pairs\t10\n")) << r.out;
  // RPE with delta 1 frame: relative motions agree exactly.
  r = RunEval("rpe " + r_path + " " + e_path + " -r angle_deg", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out,
                       "RPE w.r.t. rotation angle in degrees (deg)\nfor delta = 1 (frames) "
                       "using consecutive pairs\n(not aligned)\n"))
      << r.out;
  EXPECT_TRUE(Contains(r.out, "     pairs\t9\n")) << r.out;
}

TEST(EvalCli, BadFileGivesOneLineAndExitCode2) {
  const auto dir = test::ScratchDir();
  const std::string good = WriteText(dir, "good.txt", "1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n");
  const std::string bad = WriteText(dir, "bad.txt", "# x\n1 0 0 0 0 0 0 1\n2 1 0 0 0 0 1\n");
  CliResult r = RunEval("ape " + good + " " + bad, dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "planeslam: error: " + bad +
                       ":3: expected 8 columns 't tx ty tz qx qy qz qw' (TUM), got 7 columns\n");
  const std::string unsorted = WriteText(dir, "u.txt", "2 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n");
  r = RunEval("ape " + good + " " + unsorted + " --format tum", dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "planeslam: error: " + unsorted +
                       ":2: timestamp 1 is before the previous one (2): stamps must be sorted\n");
  // A repeated stamp is an error naming the line, unless a policy is chosen.
  const std::string dup = WriteText(dir, "dup.txt", "1 0 0 0 0 0 0 1\n1 5 0 0 0 0 0 1\n");
  r = RunEval("ape " + dup + " " + good, dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "planeslam: error: " + dup +
                       ":2: duplicate timestamp 1 (stamps must be unique); --duplicates "
                       "first|last keeps one\n");
  r = RunEval("ape " + dup + " " + good + " --duplicates last", dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, "       max\t5.000000\n")) << r.out;  // kept (5, 0, 0) vs (0, 0, 0)
  EXPECT_TRUE(Contains(r.err, "kept the last pose")) << r.err;
  // Collinear positions cannot be aligned: a clear message, not a wrong number.
  std::ostringstream line;
  for (int i = 0; i < 5; ++i) line << i << " " << i << " 0 0 0 0 0 1\n";
  const std::string straight = WriteText(dir, "line.txt", line.str());
  r = RunEval("ape " + straight + " " + straight + " -a", dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(Contains(r.err, "collinear")) << r.err;
}

TEST(EvalCli, KittiPairsByIndexAndPlotsAreValidSvg) {
  const auto dir = test::ScratchDir();
  std::ostringstream ref, est;
  for (int i = 0; i < 12; ++i) {
    const double c = std::cos(0.2 * i), s = std::sin(0.2 * i);
    ref << c << " " << -s << " 0 " << 2 * c << " " << s << " " << c << " 0 " << 2 * s
        << " 0 0 1 0\n";
    est << c << " " << -s << " 0 " << 2 * c + 0.01 * i << " " << s << " " << c << " 0 " << 2 * s
        << " 0 0 1 0\n";
  }
  const std::string r_path = WriteText(dir, "ref_kitti.txt", ref.str());
  const std::string e_path = WriteText(dir, "est_kitti.txt", est.str());
  const std::string plots = (dir / "plots").string();
  CliResult r = RunEval("rpe " + r_path + " " + e_path + " --plot " + plots, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, "     pairs\t11\n")) << r.out;
  r = RunEval("ape " + r_path + " " + e_path + " --plot " + plots, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, "       max\t0.110000\n")) << r.out;  // 0.01 x 11
  for (const char* name : {"ape_trajectories.svg", "ape_error.svg", "rpe_trajectories.svg",
                           "rpe_error.svg", "rpe_pairs.svg"}) {
    const std::filesystem::path svg = dir / "plots" / name;
    ASSERT_TRUE(std::filesystem::exists(svg)) << name;
    const std::string text = Slurp(svg);
    EXPECT_EQ(text.rfind("<?xml", 0), 0u) << name;
    EXPECT_TRUE(Contains(text, "</svg>\n")) << name;
    if (std::system("command -v xmllint >/dev/null 2>&1") == 0) {
      EXPECT_EQ(std::system(("xmllint --noout " + svg.string()).c_str()), 0) << name;
    }
  }
}

TEST(SvgPlot, EscapesTextAndDrawsEverySeries) {
  SvgPlot plot("a < b & \"c\"", "x [m]", "y [m]");
  plot.AddLine({0, 1, 2}, {0, 1, 0}, LineStyle{CycleColor(1), 2.0, true}, "dashed <line>");
  plot.AddScatter({0.5}, {0.5}, CycleColor(2), "point");
  plot.AddColorMappedScatter({0, 1}, {1, 0}, {0.0, 1.0}, "error");
  plot.AddHorizontalLine(0.25, LineStyle{}, "mean");
  plot.AddBoxes({ComputeBoxStats("run", {1, 2, 3, 4, 5})});
  const std::string svg = plot.Render();
  EXPECT_TRUE(Contains(svg, "<title>a &lt; b &amp; &quot;c&quot;</title>"));
  EXPECT_TRUE(Contains(svg, "dashed &lt;line&gt;"));
  EXPECT_TRUE(Contains(svg, "stroke-dasharray=\"6,4\""));
  EXPECT_TRUE(Contains(svg, "fill=\"url(#colorbar)\""));
  // Colour-mapped extremes are viridis' ends.
  EXPECT_TRUE(Contains(svg, "fill=\"" + ColorMap(0.0).Hex() + "\""));
  EXPECT_TRUE(Contains(svg, "fill=\"" + ColorMap(1.0).Hex() + "\""));
  EXPECT_EQ(ColorMap(0.0).Hex(), "#440154");
  EXPECT_EQ(ColorMap(1.0).Hex(), "#fde725");
  const BoxStats b = ComputeBoxStats("x", {4, 1, 3, 2, 5});
  EXPECT_DOUBLE_EQ(b.q1, 2.0);
  EXPECT_DOUBLE_EQ(b.median, 3.0);
  EXPECT_DOUBLE_EQ(b.q3, 4.0);
}

}  // namespace
}  // namespace planeslam::app

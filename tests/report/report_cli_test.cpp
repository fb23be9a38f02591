// report.html from the command line: written by `run` and `detect`, off with --no-report and
// report.enabled: false, rebuilt by `planeslam report DIR`, one-line errors on bad folders. The
// page itself is checked in a browser by report.browser (report_browser_test.sh).
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "cli_support.hpp"
#include "report.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

constexpr const char* kShortRun = " --quiet --set run.max_frames=12 --set octomap.enabled=false";

bool OneLine(const std::string& text) {
  return !text.empty() && text.find('\n') == text.size() - 1;
}

TEST(ReportCli, RunWritesASelfContainedReportAndReportRebuildsIt) {
  if (!app::ReportAvailable()) GTEST_SKIP() << app::ReportUnavailableReason();
  const fs::path dir = ScratchDir();
  const CliResult r = RunCli("run -o " + (dir / "out").string() + kShortRun, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string html = Slurp(dir / "out" / "report.html");
  ASSERT_FALSE(html.empty());
  EXPECT_TRUE(fs::exists(dir / "out" / "keyframe_cloud.pcd"));
  EXPECT_TRUE(fs::exists(dir / "out" / "ground_truth_tum.txt"));
  // Nothing is fetched at view time: no external script, style or link.
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);
  EXPECT_EQ(html.find("href=\"http"), std::string::npos);
  EXPECT_EQ(html.find("{{TITLE}}"), std::string::npos);
  EXPECT_EQ(html.find("/*{{SCRIPT}}*/"), std::string::npos);
  EXPECT_NE(html.find("\"kind\":\"run\""), std::string::npos);

  fs::remove(dir / "out" / "report.html");
  const CliResult again = RunCli("report --quiet " + (dir / "out").string(), dir);
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_EQ(Slurp(dir / "out" / "report.html"), html);
}

TEST(ReportCli, NoReportFlagAndConfigKeyTurnItOff) {
  const fs::path dir = ScratchDir();
  CliResult r = RunCli("run --no-report -o " + (dir / "a").string() + kShortRun, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "a" / "summary.json"));
  EXPECT_FALSE(fs::exists(dir / "a" / "report.html"));
  EXPECT_FALSE(fs::exists(dir / "a" / "keyframe_cloud.pcd"));
  r = RunCli("run --set report.enabled=false -o " + (dir / "b").string() + kShortRun, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(dir / "b" / "report.html"));
}

TEST(ReportCli, DetectWritesAReport) {
  if (!app::ReportAvailable()) GTEST_SKIP() << app::ReportUnavailableReason();
  const fs::path dir = ScratchDir();
  CliResult r = RunCli("simulate room --quiet --frames 1 -o " + (dir / "sim").string(), dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  fs::path depth;
  for (const auto& e : fs::directory_iterator(dir / "sim" / "depth")) depth = e.path();
  r = RunCli("detect --quiet " + depth.string() + " -o " + (dir / "det").string(), dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string html = Slurp(dir / "det" / "report.html");
  EXPECT_NE(html.find("\"kind\":\"detect\""), std::string::npos);
}

TEST(ReportCli, BadFoldersGiveOneLineErrorsAndNoReport) {
  if (!app::ReportAvailable()) GTEST_SKIP() << app::ReportUnavailableReason();
  const fs::path dir = ScratchDir();
  CliResult r = RunCli("report " + (dir / "missing").string(), dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(OneLine(r.err)) << r.err;
  EXPECT_NE(r.err.find("missing"), std::string::npos) << r.err;

  // An output folder whose summary.json is cut short.
  fs::create_directories(dir / "cut");
  WriteText(dir / "cut", "summary.json", "{\"frames\": 3, \"keyf");
  r = RunCli("report " + (dir / "cut").string(), dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(OneLine(r.err)) << r.err;
  EXPECT_NE(r.err.find("summary.json"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "cut" / "report.html"));

  // A folder with a summary but no plane map.
  WriteText(dir / "cut", "summary.json", "{\"frames\": 3, \"keyframes\": 1}");
  r = RunCli("report " + (dir / "cut").string(), dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("plane_map.json"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "cut" / "report.html"));
}

TEST(ReportHtml, DataCannotEndTheScriptElement) {
  if (!app::ReportAvailable()) GTEST_SKIP() << app::ReportUnavailableReason();
  const std::string html =
      app::AssembleReportHtml("a <b>", {{"kind", "run"}, {"text", "</script><script>x()"}});
  EXPECT_EQ(html.find("</script><script>x()"), std::string::npos);
  EXPECT_NE(html.find("<\\/script><script>x()"), std::string::npos);
  EXPECT_NE(html.find("<title>a &lt;b&gt;</title>"), std::string::npos);
}

}  // namespace
}  // namespace planeslam::test

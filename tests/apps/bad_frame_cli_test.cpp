// `planeslam run` over a sequence with an unreadable frame: run.on_bad_frame skip leaves the frame
// out and completes (exit 5), stop ends there with the outputs of the frames before it (exit 6);
// a missing listed file is a bad frame too, and a bad first frame is still an error with no output.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_support.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

const char* const kTum = "tum_fr3_structure_notexture_far";
// Half resolution as the README runs TUM; no OctoMap, to keep the runs short.
const std::string kTumArgs = "-q -c " + std::string(PLANESLAM_SOURCE_DIR) +
                             "/config/tum_fr3.yaml -c " + PLANESLAM_SOURCE_DIR +
                             "/config/detection_kinect.yaml --set octomap.enabled=false";

/// The depth files depth.txt lists, in order.
std::vector<std::string> ListedFiles(const fs::path& list) {
  std::vector<std::string> files;
  std::ifstream in(list);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    files.push_back(line.substr(line.find(' ') + 1));
  }
  return files;
}

/// A copy of the TUM folder in `dir`: its text files copied, its depth PNGs linked.
fs::path LinkTumFolder(const fs::path& dir) {
  const fs::path source = DataDir() / kTum;
  const fs::path folder = dir / "tum";
  fs::create_directories(folder / "depth");
  for (const char* name : {"depth.txt", "groundtruth.txt", "intrinsics.yaml"}) {
    fs::copy_file(source / name, folder / name);
  }
  for (const auto& entry : fs::directory_iterator(source / "depth")) {
    fs::create_symlink(entry.path(), folder / "depth" / entry.path().filename());
  }
  return folder;
}

/// Replaces the `index`-th listed PNG of `folder` by its first 5000 bytes; returns its path.
fs::path TruncateFrame(const fs::path& folder, std::size_t index) {
  const fs::path png = folder / ListedFiles(folder / "depth.txt").at(index);
  const std::string bytes = Slurp(fs::read_symlink(png)).substr(0, 5000);
  fs::remove(png);
  std::ofstream(png, std::ios::binary) << bytes;
  return png;
}

nlohmann::json ReadJson(const fs::path& path) { return nlohmann::json::parse(Slurp(path)); }

double AteRmse(const fs::path& out) {
  return ReadJson(out / "metrics.json")["ate"]["rmse"].get<double>();
}

/// The frames.csv row of frame `index`.
std::string FramesCsvRow(const fs::path& out, std::size_t index) {
  std::ifstream in(out / "frames.csv");
  std::string line;
  const std::string prefix = std::to_string(index) + ",";
  while (std::getline(in, line)) {
    if (line.rfind(prefix, 0) == 0) return line;
  }
  return "";
}

// Frame 120 of 252 (index 119) truncated: skip completes the other 251 frames about as accurately
// as the clean run; stop keeps 119 frames whose trajectory evaluates.
TEST(BadFrameCli, TruncatedPngIsSkippedOrStopsTheRun) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = ScratchDir();
  const fs::path folder = LinkTumFolder(dir);
  const fs::path bad = TruncateFrame(folder, 119);

  const CliResult clean = RunCli(
      "run " + (DataDir() / kTum).string() + " " + kTumArgs + " --out " + (dir / "clean").string(),
      dir);
  ASSERT_EQ(clean.exit_code, app::kExitSuccess) << clean.err;

  const fs::path skip_out = dir / "skip";
  const CliResult skip =
      RunCli("run " + folder.string() + " " + kTumArgs + " --out " + skip_out.string(), dir);
  ASSERT_EQ(skip.exit_code, app::kExitSkippedFrames) << skip.err;
  EXPECT_NE(skip.err.find("frame 119 skipped: " + bad.string() + ": corrupt or truncated PNG"),
            std::string::npos)
      << skip.err;
  const nlohmann::json summary = ReadJson(skip_out / "summary.json");
  EXPECT_EQ(summary["frames"].get<std::size_t>(), 251u);
  EXPECT_EQ(summary["skipped_frames"].get<std::size_t>(), 1u);
  ASSERT_EQ(summary["bad_frames"].size(), 1u);
  EXPECT_EQ(summary["bad_frames"][0]["index"].get<std::size_t>(), 119u);
  EXPECT_EQ(summary["bad_frames"][0]["file"].get<std::string>(), bad.string());
  EXPECT_NE(FramesCsvRow(skip_out, 119).find(",skipped"), std::string::npos);
  EXPECT_NEAR(AteRmse(skip_out), AteRmse(dir / "clean"), 0.0005);  // 0.05 cm

  const fs::path stop_out = dir / "stop";
  const CliResult stop = RunCli("run " + folder.string() + " " + kTumArgs +
                                    " --set run.on_bad_frame=stop --out " + stop_out.string(),
                                dir);
  ASSERT_EQ(stop.exit_code, app::kExitStoppedAtBadFrame) << stop.err;
  const nlohmann::json stopped = ReadJson(stop_out / "summary.json");
  EXPECT_EQ(stopped["frames"].get<std::size_t>(), 119u);
  EXPECT_TRUE(stopped["stopped_at_bad_frame"].get<bool>());
  EXPECT_EQ(stopped["bad_frames"][0]["index"].get<std::size_t>(), 119u);
  EXPECT_NE(FramesCsvRow(stop_out, 119).find(",stopped"), std::string::npos);
  const std::string tum = (stop_out / "trajectory_tum.txt").string();
  EXPECT_EQ(datasets::ReadTumTrajectory(tum).size(), 119u);
  const std::string gt = (folder / "groundtruth.txt").string();
  const CliResult eval = RunCli("eval ape " + gt + " " + tum + " -a", dir);
  EXPECT_EQ(eval.exit_code, 0) << eval.err;
  EXPECT_GT(ReadJson(stop_out / "metrics.json")["ate"]["pairs"].get<std::size_t>(), 100u);
}

TEST(BadFrameCli, MissingListedFileIsABadFrame) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = ScratchDir();
  const fs::path folder = LinkTumFolder(dir);
  fs::remove(folder / ListedFiles(folder / "depth.txt").at(3));
  const fs::path out = dir / "out";
  const CliResult r = RunCli(
      "run " + folder.string() + " " + kTumArgs + " --set run.max_frames=6 --out " + out.string(),
      dir);
  ASSERT_EQ(r.exit_code, app::kExitSkippedFrames) << r.err;
  EXPECT_NE(r.err.find("which does not exist"), std::string::npos) << r.err;
  const nlohmann::json summary = ReadJson(out / "summary.json");
  EXPECT_EQ(summary["frames"].get<std::size_t>(), 5u);
  EXPECT_EQ(summary["bad_frames"][0]["index"].get<std::size_t>(), 3u);
}

TEST(BadFrameCli, BadFirstFrameIsAnErrorWithNoOutput) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = ScratchDir();
  const fs::path folder = LinkTumFolder(dir);
  const fs::path bad = TruncateFrame(folder, 0);
  const fs::path out = dir / "out";
  const CliResult r = RunCli(
      "run " + folder.string() + " " + kTumArgs + " --set run.max_frames=4 --out " + out.string(),
      dir);
  EXPECT_EQ(r.exit_code, app::kExitError) << r.err;
  EXPECT_NE(r.err.find(bad.string() + ": corrupt or truncated PNG"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace planeslam::test

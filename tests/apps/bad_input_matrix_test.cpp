// The bad-input matrix through the command line: every reader and subcommand fed missing, empty,
// truncated, wrong-format and NaN/inf-filled inputs must exit with code 2 and exactly one line on
// stderr naming the offending file (or key), never crash, and leave no output files behind.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

struct BadCase {
  std::string name;
  std::string args;  ///< arguments after `planeslam`, with {dir} replaced by the scratch folder
  std::string must_name;  ///< text the error line must contain (the file, or the key)
};

std::string Replace(std::string s, const std::string& from, const std::string& to) {
  for (std::size_t pos = s.find(from); pos != std::string::npos; pos = s.find(from, pos)) {
    s.replace(pos, from.size(), to);
    pos += to.size();
  }
  return s;
}

/// Files that must not exist after a failed command: its whole output folder.
void ExpectNoOutputs(const fs::path& out) {
  if (!fs::exists(out)) return;
  std::vector<std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(out)) files.push_back(e.path().string());
  EXPECT_TRUE(files.empty()) << "left behind: " << (files.empty() ? "" : files.front());
}

void MakeBadFiles(const fs::path& dir) {
  WriteText(dir, "empty.png", "");
  WriteText(dir, "text.png", "this is not a png\n");
  // A valid PNG signature and the start of an IHDR, then nothing: truncated.
  WriteText(dir, "truncated.png", std::string("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\x02", 19));
  WriteText(dir, "empty.pcd", "");
  const std::string header =
      "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 2\n";
  WriteText(dir, "lying.pcd", header + "POINTS 5\nDATA ascii\n0 0 1\n0 1 1\n1 0 1\n1 1 1\n");
  WriteText(dir, "short.pcd", header + "POINTS 4\nDATA ascii\n0 0 1\n0 1 1\n");
  WriteText(dir, "nan.pcd", header + "POINTS 4\nDATA ascii\nnan nan nan\nnan nan nan\n"
                                     "nan nan nan\nnan nan nan\n");
  WriteText(dir, "huge.pcd",
            "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000000\n"
            "HEIGHT 1000000\nPOINTS 1000000000000\nDATA binary\n");
  WriteText(dir, "empty.txt", "");
  WriteText(dir, "seven.txt", "1.0 0 0 0 0 0 1\n");
  WriteText(dir, "words.txt", "1.0 0 0 zero 0 0 0 1\n");
  WriteText(dir, "unsorted.txt", "2.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n");
  WriteText(dir, "duplicate.txt", "1.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n");
  WriteText(dir, "inf.txt", "1.0 inf 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n");
  WriteText(dir, "good.txt", "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n3.0 2 1 0 0 0 0 1\n");
  WriteText(dir, "late.txt", "100.0 0 0 0 0 0 0 1\n101.0 1 0 0 0 0 0 1\n102.0 2 1 0 0 0 0 1\n");
  WriteText(dir, "bad_key.yaml", "detection:\n  epsilom: 0.1\n");
  WriteText(dir, "bad_value.yaml", "detection:\n  theta: -4\n");
  WriteText(dir, "not_yaml.yaml", "detection: [1, 2\n");
  WriteText(dir, "truncated.g2o", "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 1 1 0\n");
  WriteText(dir, "nan.g2o", "VERTEX_SE3:QUAT 0 nan 0 0 0 0 0 1\n");
  fs::create_directories(dir / "empty_seq");
  fs::create_directories(dir / "absent_seq");
  WriteText(dir / "absent_seq", "depth.txt", "1.0 depth/1.0.png\n1.1 depth/1.1.png\n");
  fs::create_directories(dir / "unsorted_seq/depth");
  WriteText(dir / "unsorted_seq", "depth.txt", "2.0 depth/2.png\n1.0 depth/1.png\n");
  // KITTI scans: truncated mid-point, a NaN coordinate, no bytes, no return; and a KITTI
  // sequence folder whose first scan is truncated.
  const std::string point(16, '\0');
  std::string good;
  for (int i = 1; i <= 3; ++i) {
    const float p[4] = {static_cast<float>(i), 1.0f, 0.5f, 0.3f};
    good.append(reinterpret_cast<const char*>(p), sizeof(p));
  }
  WriteText(dir, "truncated.bin", good.substr(0, 40));
  std::string nan = good;
  const float nan_value = std::numeric_limits<float>::quiet_NaN();
  nan.replace(20, 4, reinterpret_cast<const char*>(&nan_value), 4);
  WriteText(dir, "nan.bin", nan);
  WriteText(dir, "empty.bin", "");
  WriteText(dir, "origin.bin", point + point);
  fs::create_directories(dir / "kitti_seq/velodyne");
  WriteText(dir / "kitti_seq/velodyne", "000000.bin", good.substr(0, 40));
  WriteText(dir / "kitti_seq/velodyne", "000001.bin", good);
  WriteText(dir / "kitti_seq", "times.txt", "0\n0.1\n");
  fs::create_directories(dir / "badpng_seq/depth");
  WriteText(dir / "badpng_seq", "depth.txt", "1.0 depth/1.png\n");
  WriteText(dir / "badpng_seq/depth", "1.png", "not a png");
}

TEST(BadInputMatrix, EveryCommandRefusesCleanly) {
  const fs::path dir = ScratchDir();
  MakeBadFiles(dir);
  const std::vector<BadCase> cases = {
      // detect: single frames
      {"detect missing", "detect {dir}/missing.png --out {dir}/out", "missing.png"},
      {"detect empty png", "detect {dir}/empty.png --out {dir}/out", "empty.png"},
      {"detect text as png", "detect {dir}/text.png --out {dir}/out", "text.png"},
      {"detect truncated png", "detect {dir}/truncated.png --out {dir}/out", "truncated.png"},
      {"detect empty pcd", "detect {dir}/empty.pcd --out {dir}/out", "empty.pcd"},
      {"detect lying pcd", "detect {dir}/lying.pcd --out {dir}/out", "lying.pcd"},
      {"detect short pcd", "detect {dir}/short.pcd --out {dir}/out", "short.pcd"},
      {"detect all-NaN pcd", "detect {dir}/nan.pcd --out {dir}/out", "nan.pcd"},
      {"detect absurd pcd", "detect {dir}/huge.pcd --out {dir}/out", "huge.pcd"},
      {"detect bad key", "detect {dir}/lying.pcd -c {dir}/bad_key.yaml --out {dir}/out",
       "detection.epsilom"},
      {"detect bad value", "detect {dir}/lying.pcd -c {dir}/bad_value.yaml --out {dir}/out",
       "detection.theta"},
      {"detect not yaml", "detect {dir}/lying.pcd -c {dir}/not_yaml.yaml --out {dir}/out",
       "not_yaml.yaml"},
      {"detect missing config", "detect {dir}/lying.pcd -c {dir}/nope.yaml --out {dir}/out",
       "nope.yaml"},
      {"detect truncated bin", "detect {dir}/truncated.bin --out {dir}/out", "truncated.bin"},
      {"detect NaN bin", "detect {dir}/nan.bin --out {dir}/out", "nan.bin"},
      {"detect empty bin", "detect {dir}/empty.bin --out {dir}/out", "empty.bin"},
      {"detect bin without returns", "detect {dir}/origin.bin --out {dir}/out", "origin.bin"},
      // run: sequences
      {"run missing folder", "run {dir}/no_such_seq --out {dir}/out", "no_such_seq"},
      {"run empty folder", "run {dir}/empty_seq --out {dir}/out", "empty_seq"},
      {"run absent frames", "run {dir}/absent_seq --out {dir}/out", "1.0.png"},
      {"run unsorted stamps", "run {dir}/unsorted_seq --out {dir}/out", "depth.txt"},
      {"run corrupt frame", "run {dir}/badpng_seq --out {dir}/out", "1.png"},
      {"run truncated first scan", "run {dir}/kitti_seq --out {dir}/out", "000000.bin"},
      {"run bad key", "run -c {dir}/bad_key.yaml --out {dir}/out", "detection.epsilom"},
      // eval: trajectories
      {"eval missing", "eval ape {dir}/missing.txt {dir}/good.txt", "missing.txt"},
      {"eval empty", "eval ape {dir}/empty.txt {dir}/good.txt", "empty.txt"},
      {"eval seven columns", "eval ape {dir}/seven.txt {dir}/good.txt", "seven.txt:1"},
      {"eval text in number", "eval ape {dir}/good.txt {dir}/words.txt", "words.txt:1"},
      {"eval unsorted", "eval ape {dir}/unsorted.txt {dir}/good.txt", "unsorted.txt:2"},
      {"eval duplicate", "eval ape {dir}/duplicate.txt {dir}/good.txt", "duplicate.txt:2"},
      {"eval inf", "eval ape {dir}/inf.txt {dir}/good.txt", "inf.txt:1"},
      {"eval no overlap", "eval ape {dir}/good.txt {dir}/late.txt", "late.txt"},
      {"eval kitti too short", "eval kitti {dir}/good.txt {dir}/good.txt", "good.txt"},
      // graph
      {"graph missing", "graph optimize {dir}/missing.g2o --out {dir}/out/g.g2o", "missing.g2o"},
      {"graph truncated", "graph optimize {dir}/truncated.g2o --out {dir}/out/g.g2o",
       "truncated.g2o:2"},
      {"graph nan", "graph optimize {dir}/nan.g2o --out {dir}/out/g.g2o", "nan.g2o:1"},
      // simulate
      {"simulate bad value", "simulate room -c {dir}/bad_value.yaml --out {dir}/out",
       "detection.theta"},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.name);
    fs::remove_all(dir / "out");
    const CliResult r = RunCli(Replace(c.args, "{dir}", dir.string()), dir);
    EXPECT_EQ(r.signal, 0) << "crashed with signal " << r.signal;
    EXPECT_EQ(r.exit_code, 2) << r.err;
    // The error is the last stderr line (a command may announce its input on a line before).
    ASSERT_FALSE(r.err.empty());
    ASSERT_EQ(r.err.back(), '\n') << r.err;
    const std::size_t start = r.err.rfind('\n', r.err.size() - 2);
    const std::string line = r.err.substr(start == std::string::npos ? 0 : start + 1);
    EXPECT_EQ(line.rfind("planeslam: ", 0), 0u) << r.err;
    EXPECT_NE(line.find("error"), std::string::npos) << r.err;
    EXPECT_NE(line.find(c.must_name), std::string::npos) << r.err;
    ExpectNoOutputs(dir / "out");
  }
}

}  // namespace
}  // namespace planeslam::test

// `planeslam run` gives the same outputs whatever its thread count: every file byte for byte,
// except the timing fields (summary.json's time_ms, frames_per_second and the back end's ms per
// frame, also embedded in report.html) and the run.threads line of config.yaml. Also the ordered
// pipeline the run reads ahead with: items in order, exceptions delivered with their item; and
// `detect` on several inputs.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "cli_support.hpp"
#include "pipeline.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

/// `yaml` without its run.threads line.
std::string WithoutThreadsLine(const std::string& yaml) {
  std::istringstream in(yaml);
  std::string line, out;
  while (std::getline(in, line)) {
    if (line.rfind("  threads:", 0) == 0) continue;
    out += line + "\n";
  }
  return out;
}

/// A run's summary without its timing fields.
nlohmann::json WithoutTimes(nlohmann::json summary) {
  summary.erase("time_ms");
  summary.erase("frames_per_second");
  if (summary.contains("back_end")) {
    summary["back_end"].erase("slam_ms_per_frame_first");
    summary["back_end"].erase("slam_ms_per_frame_last");
  }
  return summary;
}

/// report.html with the timing fields of its embedded data removed.
std::string ReportWithoutTimes(const std::string& html) {
  const std::string open = "<script type=\"application/json\" id=\"planeslam-data\">";
  const std::size_t begin = html.find(open);
  if (begin == std::string::npos) return html;
  const std::size_t data = begin + open.size();
  const std::size_t end = html.find("</script>", data);
  nlohmann::json parsed = nlohmann::json::parse(html.substr(data, end - data));
  if (parsed.contains("summary")) parsed["summary"] = WithoutTimes(parsed["summary"]);
  if (parsed.contains("config_yaml")) {
    parsed["config_yaml"] = WithoutThreadsLine(parsed["config_yaml"].get<std::string>());
  }
  return html.substr(0, data) + parsed.dump() + html.substr(end);
}

/// Compares every file of `a` with its namesake in `b` (timing fields aside); returns how many.
int CompareOutputs(const fs::path& a, const fs::path& b) {
  int compared = 0;
  for (const auto& entry : fs::recursive_directory_iterator(a)) {
    if (!entry.is_regular_file()) continue;
    const fs::path other = b / fs::relative(entry.path(), a);
    const std::string name = entry.path().filename().string();
    if (!fs::exists(other)) {
      ADD_FAILURE() << "missing: " << other;
      continue;
    }
    const std::string x = Slurp(entry.path()), y = Slurp(other);
    if (name == "summary.json") {
      EXPECT_EQ(WithoutTimes(nlohmann::json::parse(x)), WithoutTimes(nlohmann::json::parse(y)))
          << "differs: " << other;
    } else if (name == "config.yaml") {
      EXPECT_TRUE(WithoutThreadsLine(x) == WithoutThreadsLine(y)) << "differs: " << other;
    } else if (name == "report.html") {
      EXPECT_TRUE(ReportWithoutTimes(x) == ReportWithoutTimes(y)) << "differs: " << other;
    } else {
      EXPECT_TRUE(x == y) << "differs: " << other;
    }
    ++compared;
  }
  for (const auto& entry : fs::recursive_directory_iterator(b)) {
    if (entry.is_regular_file()) {
      EXPECT_TRUE(fs::exists(a / fs::relative(entry.path(), b))) << "extra: " << entry.path();
    }
  }
  return compared;
}

/// Runs `args` with each of `threads` and compares the outputs with those of the first.
void ExpectSameForThreadCounts(const std::string& args, int min_files,
                               const std::vector<std::string>& threads = {"1", "2", "3"}) {
  const fs::path dir = ScratchDir();
  for (const std::string& t : threads) {
    const CliResult r =
        RunCli("run " + args + " --threads " + t + " --out " + (dir / t).string(), dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  for (std::size_t i = 1; i < threads.size(); ++i) {
    EXPECT_GE(CompareOutputs(dir / threads[0], dir / threads[i]), min_files) << threads[i];
  }
}

// The room with its loop closures, OctoMap and report: 10 files and more.
TEST(ThreadDeterminism, RoomSameForOneTwoThreeThreads) {
  ExpectSameForThreadCounts("-q --set run.max_frames=70", 10);
}

// A second, independent scene, every second frame at half resolution.
TEST(ThreadDeterminism, CorridorStrideDecimationSameForThreadCounts) {
  ExpectSameForThreadCounts(
      "-q --scene corridor --set run.max_frames=30 --set run.frame_stride=2 "
      "--set run.decimation=2",
      10);
}

// The TUM folder with its profile (OctoMap, report), as the README runs it.
TEST(ThreadDeterminism, TumFolderSameForOneTwoThreads) {
  PLANESLAM_REQUIRE_DATA();
  ExpectSameForThreadCounts("-q " + (DataDir() / "tum_fr3_structure_notexture_far").string(),
                            10, {"1", "2"});
}

// The KITTI scans with their profile: LiDAR tracking and the outdoor OctoMap, whose scans are
// ray-cast on several threads.
TEST(ThreadDeterminism, KittiScansSameForOneTwoThreads) {
  PLANESLAM_REQUIRE_DATA();
  ExpectSameForThreadCounts(
      "-q " + (DataDir() / "kitti_velodyne").string() + " --set run.max_frames=4", 10, {"1", "2"});
}

// Randomised delays (fixed seed, 20 draws): whatever order the workers finish in, items come out
// in index order, each once; a throwing item delivers its exception in its turn.
TEST(OrderedPipeline, ItemsInOrderWhateverTheDelays) {
  std::mt19937 rng(35);
  for (int draw = 0; draw < 20; ++draw) {
    const std::size_t count = 1 + rng() % 60, workers = 1 + rng() % 4, depth = 1 + rng() % 6;
    const std::size_t bad = rng() % (count + 5);  // beyond count: no item throws
    std::vector<int> delays(count);
    for (int& d : delays) d = static_cast<int>(rng() % 300);
    std::atomic<int> in_flight{0}, most_in_flight{0};
    app::OrderedPipeline<std::size_t> pipeline(
        count, workers, depth, [&](std::size_t i, std::size_t worker) {
          EXPECT_LT(worker, workers);
          const int now = ++in_flight;
          int seen = most_in_flight.load();
          while (now > seen && !most_in_flight.compare_exchange_weak(seen, now)) {
          }
          std::this_thread::sleep_for(std::chrono::microseconds(delays[i]));
          --in_flight;
          if (i == bad) throw std::runtime_error("item " + std::to_string(i));
          return i * 7;
        });
    for (std::size_t i = 0; i < count; ++i) {
      if (i == bad) {
        EXPECT_THROW(pipeline.Take(), std::runtime_error) << "draw " << draw;
      } else {
        EXPECT_EQ(pipeline.Take(), i * 7) << "draw " << draw;
      }
    }
    EXPECT_LE(most_in_flight.load(), static_cast<int>(std::min(workers, depth)));
  }
}

// The pipeline is left early (an interrupted run): its destructor stops and joins the workers.
TEST(OrderedPipeline, LeftEarlyJoinsCleanly) {
  std::atomic<int> made{0};
  {
    app::OrderedPipeline<int> pipeline(1000, 3, 4, [&](std::size_t i, std::size_t) {
      ++made;
      return static_cast<int>(i);
    });
    EXPECT_EQ(pipeline.Take(), 0);
    EXPECT_EQ(pipeline.Take(), 1);
  }
  EXPECT_LE(made.load(), 2 + 4);  // the two taken and at most `depth` ahead
}

TEST(ParallelFor, EveryIndexOnceAndFirstErrorRethrown) {
  for (std::size_t threads : {1, 2, 5}) {
    std::vector<int> hits(97, 0);
    app::ParallelFor(hits.size(), threads, [&](std::size_t i) { ++hits[i]; });
    for (int h : hits) EXPECT_EQ(h, 1);
    EXPECT_THROW(app::ParallelFor(10, threads,
                                  [](std::size_t i) {
                                    if (i == 3) throw std::runtime_error("three");
                                  }),
                 std::runtime_error);
  }
}

/// planes.json without its timing fields.
nlohmann::json PlanesWithoutTimes(const fs::path& file) {
  nlohmann::json planes = nlohmann::json::parse(Slurp(file));
  planes.erase("detect_ms");
  planes.erase("timings_ms");
  return planes;
}

// `detect` on several inputs (in parallel): one folder per input with the files a run on that
// input alone writes; an unreadable input is reported and skipped (exit 5).
TEST(DetectSeveralInputs, SameFilesAsOneByOneAndBadInputSkipped) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = ScratchDir();
  const fs::path depth = DataDir() / "tum_fr3_structure_notexture_far" / "depth";
  std::vector<fs::path> pngs;
  for (const auto& entry : fs::directory_iterator(depth)) pngs.push_back(entry.path());
  std::sort(pngs.begin(), pngs.end());
  pngs.resize(3);
  const std::string common = " --set report.enabled=false -q";
  std::string all;
  for (const fs::path& png : pngs) all += png.string() + " ";
  const CliResult several =
      RunCli("detect " + all + (dir / "missing.png").string() + " --out " +
                 (dir / "several").string() + common,
             dir);
  EXPECT_EQ(several.exit_code, 5) << several.err;
  EXPECT_NE(several.err.find("missing.png"), std::string::npos) << several.err;
  for (const fs::path& png : pngs) {
    const std::string stem = png.stem().string();
    const CliResult one =
        RunCli("detect " + png.string() + " --out " + (dir / stem).string() + common, dir);
    ASSERT_EQ(one.exit_code, 0) << one.err;
    EXPECT_EQ(PlanesWithoutTimes(dir / stem / "planes.json"),
              PlanesWithoutTimes(dir / "several" / stem / "planes.json"));
    for (const char* file : {"labels.png", "segmented.ply", "config.yaml"}) {
      EXPECT_TRUE(Slurp(dir / stem / file) == Slurp(dir / "several" / stem / file)) << file;
    }
  }
  EXPECT_FALSE(fs::exists(dir / "several" / "missing"));
}

}  // namespace
}  // namespace planeslam::test

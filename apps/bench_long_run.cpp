#include "bench_long_run.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <vector>

#include "closure_report.hpp"
#include "config_sections_app.hpp"
#include "config_sections_slam.hpp"
#include "config_sections_synthetic.hpp"
#include "detector_factory.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "sensor_profiles.hpp"

namespace planeslam::app::bench {
namespace {

namespace ds = planeslam::datasets;
using Clock = std::chrono::steady_clock;

struct Case {
  std::string name;
  std::vector<std::string> overrides;  ///< "section.key=value" over the bench's config
};

/// SLAM time per frame of the last whole lap over that of the second, the first with loop
/// closures (0 for fewer than three laps): the first and last 500 frames of a run cover different
/// parts of a lap, and the first lap has no closure work.
double LapTimeRatio(const std::vector<double>& frame_ms, double laps) {
  const int whole = static_cast<int>(laps);
  if (whole < 3) return 0.0;
  const double per_lap = static_cast<double>(frame_ms.size()) / laps;
  const auto mean = [&](int lap) {
    const auto begin = static_cast<std::size_t>(std::lround(lap * per_lap));
    const auto end = static_cast<std::size_t>(std::lround((lap + 1) * per_lap));
    double sum = 0.0;
    for (std::size_t i = begin; i < end; ++i) sum += frame_ms[i];
    return end > begin ? sum / static_cast<double>(end - begin) : 0.0;
  };
  const double second = mean(1);
  return second > 0 ? mean(whole - 1) / second : 0.0;
}

/// Largest position error with the estimate aligned (SE(3)) on its first `n` frames [m].
double MaxErrorAlignedOnFirst(const ds::Trajectory& truth, const ds::Trajectory& estimate, int n) {
  ds::ApeOptions options;
  options.alignment.align = true;
  options.alignment.n_to_align = n;
  const ds::ApeResult ape = ds::EvaluateApe(truth, estimate, options);
  return ape.ok ? ape.stats.max : -1.0;
}

nlohmann::json RunCase(const ConfigOptions& base, const Case& c, bool quiet) {
  ConfigOptions options = base;
  options.overrides.insert(options.overrides.end(), c.overrides.begin(), c.overrides.end());
  options.overrides.push_back("octomap.enabled=false");
  const Config config = LoadConfigWithProfile(options, "", "", "bench long-run");
  const auto sequence = MakeSyntheticSequence("", config);
  const auto detector = MakeDetector(config.Get<DetectionSection>("detection").method, config);
  const auto slam = MakeSlamSystem(config);
  slam->SetInitialPose(*sequence->GroundTruth(0));
  slam->PlanRun(sequence->Size());
  ds::Trajectory truth;
  std::vector<double> frame_ms;
  const auto start = Clock::now();
  for (std::size_t i = 0; i < sequence->Size(); ++i) {
    const ds::Frame frame = sequence->Load(i);
    const detection::Segmentation segmentation = detector->Detect(frame.cloud);
    const auto slam_start = Clock::now();
    slam->ProcessFrame(frame.timestamp, frame.cloud, segmentation);
    frame_ms.push_back(
        std::chrono::duration<double, std::milli>(Clock::now() - slam_start).count());
    truth.Add(frame.timestamp, *frame.T_world_sensor_gt);
    if (!quiet && i % 500 == 0) std::fprintf(stderr, "\r%s: frame %zu", c.name.c_str(), i);
  }
  slam->Finish();
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  if (!quiet) std::fprintf(stderr, "\r%s: done            \n", c.name.c_str());
  const ds::Trajectory estimate = slam->EstimatedTrajectory();
  ds::ApeOptions ape_options;
  ape_options.alignment.align = true;
  const ds::ApeResult ape = ds::EvaluateApe(truth, estimate, ape_options);
  const nlohmann::json back_end = BackEndJson(*slam);
  const double first = back_end["slam_ms_per_frame_first"].get<double>();
  return {{"case", c.name},
          {"overrides", c.overrides},
          {"frames", sequence->Size()},
          {"keyframes", slam->stats().keyframes},
          {"ate_cm", ape.ok ? 100.0 * ape.stats.rmse : -1.0},
          {"max_error_aligned_first_300_cm", 100.0 * MaxErrorAlignedOnFirst(truth, estimate, 300)},
          {"map_planes", slam->map().size()},
          {"closures", ClosuresJson(*slam, truth)},
          {"optimize_share", slam->stats().time_optimize_ms / 1000.0 / seconds},
          {"time_ratio_last_first",
           first > 0 ? back_end["slam_ms_per_frame_last"].get<double>() / first : 0.0},
          {"time_ratio_last_second_lap",
           LapTimeRatio(frame_ms, config.Get<SimulationConfig>("simulation").laps)},
          {"seconds", seconds}};
}

void PrintRow(const nlohmann::json& r) {
  const nlohmann::json& closures = r["closures"];
  const std::size_t false_accepted =
      closures.contains("ground_truth")
          ? closures["ground_truth"]["false_accepted"].get<std::size_t>()
          : 0;
  const double lap_ratio = r["time_ratio_last_second_lap"].get<double>();
  char lap[16] = "     -";
  if (lap_ratio > 0) std::snprintf(lap, sizeof(lap), "%6.2f", lap_ratio);
  std::printf("%-28s %6zu %7.3f %8.2f %6zu %8zu %6zu %8zu %7.1f%% %6.2f %s\n",
              r["case"].get<std::string>().c_str(), r["frames"].get<std::size_t>(),
              r["ate_cm"].get<double>(), r["max_error_aligned_first_300_cm"].get<double>(),
              r["map_planes"].get<std::size_t>(), closures["accepted"].get<std::size_t>(),
              false_accepted, closures["retracted"].get<std::size_t>(),
              100.0 * r["optimize_share"].get<double>(), r["time_ratio_last_first"].get<double>(),
              lap);
  std::fflush(stdout);
}

}  // namespace

int RunLongRunBench(const ConfigOptions& config_options, const LongRunOptions& options) {
  std::vector<Case> cases;
  cases.push_back({"room 1.5 laps", {}});
  for (int n : options.injected) {
    cases.push_back({"room +" + std::to_string(n) + " false closures",
                     {"slam.inject_false_closures=" + std::to_string(n)}});
  }
  cases.push_back({"ring", {"simulation.scene=ring"}});
  cases.push_back({"ring, loop closure off", {"simulation.scene=ring", "slam.loop_closure=false"}});
  for (int seed : options.seeds) {
    char laps[32];
    std::snprintf(laps, sizeof(laps), "%g", options.laps);
    cases.push_back(
        {std::string("room ") + laps + " laps, seed " + std::to_string(seed),
         {"simulation.laps=" + std::string(laps), "simulation.seed=" + std::to_string(seed)}});
  }
  std::printf(
      "bench long-run: ATE [cm], max error aligned on the first 300 frames [cm], map "
      "planes, closures, optimisation share of the run, SLAM time per frame last 500 / "
      "first 500 and last lap / second lap (timings depend on the machine's load)\n");
  std::printf("%-28s %6s %7s %8s %6s %8s %6s %8s %8s %6s %6s\n", "case", "frames", "ATE", "max300",
              "planes", "accepted", "false", "retract", "optimise", "t_last", "t_lap");
  nlohmann::json results = nlohmann::json::array();
  for (const Case& c : cases) {
    results.push_back(RunCase(config_options, c, options.quiet));
    PrintRow(results.back());
  }
  if (!options.json_path.empty()) {
    ds::WriteFileAtomic(options.json_path, results.dump(2) + "\n");
  }
  return kExitSuccess;
}

}  // namespace planeslam::app::bench

// `planeslam run [SEQUENCE]`: offline plane SLAM over a sequence (or the built-in synthetic room),
// writing the trajectory, the plane map, the pose graph, an optional OctoMap and, with ground
// truth, its own scores.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include "cli_common.hpp"
#include "command_registry.hpp"
#include "config_sections_app.hpp"
#include "config_sections_datasets.hpp"
#include "config_sections_mapping.hpp"
#include "config_sections_slam.hpp"
#include "config_sections_synthetic.hpp"
#include "detector_factory.hpp"
#include "exit_codes.hpp"
#include "interrupt.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "planeslam/mapping/g2o_io.hpp"
#include "planeslam/mapping/map_writers.hpp"
#include "planeslam/mapping/occupancy_map.hpp"
#include "planeslam/mapping/slam_system.hpp"
#include "sensor_profiles.hpp"
#include "trajectory_plots.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;
using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

nlohmann::json StatsJson(const ds::ErrorStatistics& s, std::size_t pairs) {
  return {{"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"std", s.std},
          {"min", s.min},   {"max", s.max},   {"sse", s.sse},       {"pairs", pairs}};
}

/// The sequence `planeslam run` reads and the name it reports it by.
struct RunInput {
  std::unique_ptr<ds::Sequence> sequence;
  std::string name;
};

/// A sequence folder, or the synthetic scene when no folder is given.
RunInput OpenInput(const std::string& sequence_path, const std::string& scene,
                   const Config& config) {
  RunInput input;
  if (sequence_path.empty()) {
    input.sequence = MakeSyntheticSequence(scene, config);
    input.name = "synthetic " + input.sequence->Name();
  } else {
    if (!scene.empty()) throw ConfigError("--scene applies only without SEQUENCE");
    input.sequence = ds::OpenSequence(sequence_path, config.Get<ds::SensorConfig>("sensor"));
    input.name = sequence_path;
  }
  return input;
}

/// The frame indices to process: every run.frame_stride-th, at most run.max_frames of them.
std::vector<std::size_t> FrameIndices(const RunInput& input, const RunConfig& run) {
  std::vector<std::size_t> indices;
  const std::size_t frames = input.sequence->Size();
  for (std::size_t i = 0; i < frames; i += run.frame_stride) indices.push_back(i);
  if (run.max_frames > 0 && indices.size() > static_cast<std::size_t>(run.max_frames)) {
    indices.resize(run.max_frames);
  }
  if (indices.empty()) throw IoError(input.name, "the sequence has no frames");
  return indices;
}

/// A frame the sequence could not read: where it is and the reader's one-line error.
struct BadFrame {
  std::size_t index = 0;
  double timestamp = 0.0;  ///< [s] from the frame list
  std::string file;        ///< the file the error names
  std::string error;       ///< the reader's message, "FILE: reason"
};

/// What the frame loop collects besides the SLAM system's own state.
struct FrameLoopLog {
  std::size_t done = 0;              ///< frames processed
  bool interrupted = false;          ///< SIGINT/SIGTERM ended the loop
  std::vector<BadFrame> bad_frames;  ///< left out (skip) or the one that ended the loop (stop)
  bool stopped_at_bad_frame = false;
  double time_load = 0, time_detect = 0;  ///< [ms] summed over the frames
  /// Thinned clouds of the keyframes by keyframe id, inserted into the OctoMap at the end with
  /// the optimised keyframe poses.
  std::vector<std::pair<std::int64_t, std::vector<Eigen::Vector3f>>> keyframe_clouds;
  ds::Trajectory ground_truth;
  std::ostringstream frame_log;  ///< frames.csv: what the tracker did with each frame
};

/// One line of frames.csv.
void LogFrame(std::size_t index, double timestamp, const mapping::SlamFrameResult& result,
              std::ostringstream& log) {
  log << index << "," << ds::FormatRoundTrip(timestamp) << "," << result.keyframe << ","
      << result.planes << "," << result.matches << "," << result.tracked << "," << result.degenerate
      << "," << result.used_point_to_plane << "," << result.loop_closures << "," << result.refused
      << ",ok," << result.constrained_by << "," << result.weak_directions << "\n";
}

/// Loads frame `index`; a frame the sequence cannot read is recorded in `log` (frames.csv row,
/// warning) and yields nothing. The first frame of the run has nothing to fall back on, so its
/// error propagates and nothing is written.
std::optional<ds::Frame> LoadOrRecordBad(const RunInput& input, std::size_t index, bool first,
                                         const RunConfig& run, FrameLoopLog* log) {
  try {
    return input.sequence->Load(index);
  } catch (const IoError& e) {
    if (first) throw;
    BadFrame bad{index, input.sequence->Timestamp(index), e.file(), e.what()};
    const bool stop = run.on_bad_frame == "stop";
    std::cerr << (::isatty(STDERR_FILENO) ? "\n" : "")
              << "planeslam run: " << (stop ? "error" : "warning") << ": frame " << index
              << (stop ? " stops the run" : " skipped") << ": " << bad.error << "\n";
    log->frame_log << index << "," << ds::FormatRoundTrip(bad.timestamp) << ",,,,,,,,,"
                   << (stop ? "stopped" : "skipped") << ",,\n";
    log->bad_frames.push_back(std::move(bad));
    log->stopped_at_bad_frame = stop;
    return std::nullopt;
  }
}

/// Loads, decimates, detects and tracks each frame of `indices` until done or interrupted.
void ProcessFrames(const RunInput& input, const std::vector<std::size_t>& indices,
                   const RunConfig& run, const detection::PlaneDetector& detector,
                   const mapping::OccupancyMapConfig* octomap, bool quiet,
                   mapping::SlamSystem& slam, FrameLoopLog* log) {
  ProgressBar progress("run", indices.size(), quiet);
  log->frame_log << "index,timestamp,keyframe,planes,matches,tracked,degenerate,point_to_plane,"
                    "loop_closures,refused,status,constrained_by,weak_directions\n";
  for (std::size_t i : indices) {
    if (StopRequested()) {
      log->interrupted = true;
      break;
    }
    auto t = Clock::now();
    std::optional<ds::Frame> loaded = LoadOrRecordBad(input, i, i == indices.front(), run, log);
    log->time_load += MsSince(t);
    if (log->stopped_at_bad_frame) break;
    if (!loaded) continue;
    ds::Frame& frame = *loaded;
    t = Clock::now();
    if (run.decimation > 1) frame.cloud = ds::Decimate(frame.cloud, run.decimation);
    const detection::Segmentation segmentation = detector.Detect(frame.cloud);
    log->time_detect += MsSince(t);
    const mapping::SlamFrameResult result =
        slam.ProcessFrame(frame.timestamp, frame.cloud, segmentation);
    if (frame.T_world_sensor_gt) log->ground_truth.Add(frame.timestamp, *frame.T_world_sensor_gt);
    LogFrame(i, frame.timestamp, result, log->frame_log);
    if (octomap != nullptr && result.keyframe) {
      log->keyframe_clouds.emplace_back(
          static_cast<std::int64_t>(slam.stats().keyframes - 1),
          mapping::VoxelDownsample(frame.cloud.points, octomap->downsample_voxel));
    }
    progress.Update(++log->done);
  }
  progress.Finish();
}

/// The trajectory, plane map, pose graph, effective configuration and frame log.
void WriteMapOutputs(const std::string& out_dir, const mapping::SlamSystem& slam,
                     const ds::Trajectory& estimate, const Config& config,
                     const FrameLoopLog& log) {
  ds::WriteTumTrajectory(out_dir + "/trajectory_tum.txt", estimate);
  ds::WriteKittiTrajectory(out_dir + "/trajectory_kitti.txt", estimate);
  const auto records = mapping::MakeMapRecords(slam.map());
  mapping::WritePlaneMapPly(out_dir + "/plane_map.ply", records);
  mapping::WritePlaneMapObj(out_dir + "/plane_map.obj", records);
  mapping::WritePlaneMapJson(out_dir + "/plane_map.json", records);
  mapping::WriteG2o(slam.graph(), out_dir + "/pose_graph.g2o");
  ds::WriteFileAtomic(out_dir + "/config.yaml", config.ToYaml(true));
  ds::WriteFileAtomic(out_dir + "/frames.csv", log.frame_log.str());
}

/// The keyframes' thinned clouds inserted at their optimised poses, written as octomap.bt.
void WriteOctomap(const std::string& out_dir, const mapping::OccupancyMapConfig& config,
                  const mapping::SlamSystem& slam, const FrameLoopLog& log) {
  mapping::OccupancyMapConfig thinned = config;
  thinned.downsample_voxel = 0.0;  // already thinned per keyframe
  mapping::OccupancyMapBuilder octomap(thinned);
  const auto poses = slam.KeyframePoses();
  for (const auto& [id, points] : log.keyframe_clouds) octomap.Insert(points, poses.at(id));
  octomap.Write(out_dir + "/octomap.bt");
}

/// ATE (evo association, SE(3) Umeyama alignment) and RPE (evo, delta 1 frame) against the
/// ground truth, plus plots.
nlohmann::json Score(const ds::Trajectory& ground_truth, const ds::Trajectory& estimate,
                     const RunConfig& run, const std::string& out_dir) {
  ds::ApeOptions ape_options;
  ape_options.association.max_diff = run.ate_max_time_difference;
  ape_options.alignment.align = true;
  const ds::ApeResult ape =
      ds::EvaluateApe(ground_truth, estimate, ape_options, "ground truth", "trajectory_tum.txt");
  nlohmann::json metrics;
  if (!ape.ok) return {{"error", ape.message}};
  metrics["ate"] = StatsJson(ape.stats, ape.pairs.size());
  metrics["ate"]["alignment"] = "SE(3) Umeyama (evo -a)";
  ds::RpeOptions rpe_options;
  rpe_options.association.max_diff = run.ate_max_time_difference;
  rpe_options.delta = 1.0;
  rpe_options.delta_unit = ds::DeltaUnit::kFrames;
  const ds::RpeResult rpe_t = ds::EvaluateRpe(ground_truth, estimate, rpe_options);
  rpe_options.relation = ds::PoseRelation::kRotationAngleDeg;
  const ds::RpeResult rpe_r = ds::EvaluateRpe(ground_truth, estimate, rpe_options);
  if (rpe_t.ok)
    metrics["rpe_translation_m_per_frame"] = StatsJson(rpe_t.stats, rpe_t.errors.size());
  if (rpe_r.ok) metrics["rpe_rotation_deg_per_frame"] = StatsJson(rpe_r.stats, rpe_r.errors.size());
  EnsureDirectory(out_dir + "/plots");
  PlotTrajectories(out_dir + "/plots/trajectories.svg",
                   "planeslam run: trajectories, top view (SE(3) aligned)", ape.ref_poses,
                   ape.est_poses, ape.est_poses, ape.errors, "ATE [m]");
  PlotErrorOverTime(out_dir + "/plots/ate_over_time.svg", "ATE over time (SE(3) aligned)",
                    ape.stamps, ape.errors, ape.stats, "ATE [m]");
  return metrics;
}

/// "ATE rmse ... cm (...)" from Score's metrics.
std::string AteLine(nlohmann::json metrics) {
  if (metrics.contains("error")) return "ATE not computed: " + metrics["error"].get<std::string>();
  std::ostringstream os;
  os << "ATE rmse " << metrics["ate"]["rmse"].get<double>() * 100.0 << " cm (SE(3) aligned, "
     << metrics["ate"]["pairs"].get<std::size_t>() << " pairs)";
  return os.str();
}

/// Times of the stages after the frame loop [ms] and the run's wall time [s].
struct FinishTimes {
  double finish_ms = 0.0;  ///< the final optimisation
  double write_ms = 0.0;
  double wall_seconds = 0.0;
};

nlohmann::json BadFramesJson(const std::vector<BadFrame>& bad_frames) {
  nlohmann::json list = nlohmann::json::array();
  for (const BadFrame& b : bad_frames) {
    list.push_back(
        {{"index", b.index}, {"timestamp", b.timestamp}, {"file", b.file}, {"error", b.error}});
  }
  return list;
}

nlohmann::json SummaryJson(const std::string& input_name, const mapping::SlamSystem& slam,
                           const mapping::PoseGraphResult& final_optimization,
                           const FrameLoopLog& log, const FinishTimes& times) {
  const mapping::SlamStats& stats = slam.stats();
  return {{"input", input_name},
          {"frames", log.done},
          {"interrupted", log.interrupted},
          {"skipped_frames", log.stopped_at_bad_frame ? 0 : log.bad_frames.size()},
          {"stopped_at_bad_frame", log.stopped_at_bad_frame},
          {"bad_frames", BadFramesJson(log.bad_frames)},
          {"keyframes", stats.keyframes},
          {"loop_closures", stats.loop_closures},
          {"loop_candidates", stats.loop_candidates},
          {"loop_refused",
           {{"degenerate", stats.loop_refused_degenerate},
            {"matches", stats.loop_refused_matches},
            {"residual", stats.loop_refused_residual}}},
          {"refused_frames", stats.refused_frames},
          {"degenerate_frames", stats.degenerate_frames},
          {"point_to_plane_frames", stats.point_to_plane_frames},
          {"prior_frames", stats.prior_frames},
          {"untracked_frames", stats.untracked_frames},
          {"map_planes", slam.map().size()},
          {"final_optimization",
           {{"initial_cost", final_optimization.initial_cost},
            {"final_cost", final_optimization.final_cost},
            {"iterations", final_optimization.iterations},
            {"converged", final_optimization.converged}}},
          {"time_ms",
           {{"load", log.time_load},
            {"detect", log.time_detect},
            {"track", stats.time_tracking_ms},
            {"map", stats.time_map_ms},
            {"loop", stats.time_loop_ms},
            {"optimize", stats.time_optimize_ms + times.finish_ms},
            {"write", times.write_ms}}},
          {"frames_per_second", log.done / std::max(times.wall_seconds, 1e-9)}};
}

void PrintReport(const mapping::SlamSystem& slam, const FrameLoopLog& log, const FinishTimes& times,
                 const std::string& ate_line, const std::string& out_dir) {
  const mapping::SlamStats& stats = slam.stats();
  const std::size_t done = log.done;
  const char* prefix = log.interrupted ? "INTERRUPTED: outputs cover the frames processed: "
                       : log.stopped_at_bad_frame
                           ? "STOPPED AT A BAD FRAME: outputs cover the frames "
                             "before it: "
                           : "";
  std::printf("%s%zu frames (%.1f frames/s), %zu keyframes, %zu loop closures, %zu map planes\n",
              prefix, done, done / std::max(times.wall_seconds, 1e-9), stats.keyframes,
              stats.loop_closures, slam.map().size());
  std::printf(
      "degenerate frames %zu (filled by point-to-plane alignment: %zu), untracked frames %zu "
      "(refused by the prior gate: %zu), frames with a direction from the prior %zu\n",
      stats.degenerate_frames, stats.point_to_plane_frames, stats.untracked_frames,
      stats.refused_frames, stats.prior_frames);
  std::printf("loop candidates %zu, refused: degenerate %zu, few matches %zu, residual %zu\n",
              stats.loop_candidates, stats.loop_refused_degenerate, stats.loop_refused_matches,
              stats.loop_refused_residual);
  if (!log.bad_frames.empty() && !log.stopped_at_bad_frame) {
    std::printf("SKIPPED %zu unreadable frame(s):", log.bad_frames.size());
    for (const BadFrame& b : log.bad_frames) std::printf(" %zu", b.index);
    std::printf(" (see summary.json)\n");
  }
  std::printf("%s\n", ate_line.c_str());
  std::printf(
      "time per frame [ms]: load %.2f detect %.2f track %.2f map %.2f loop %.2f; "
      "optimise %.1f ms total\n",
      log.time_load / done, log.time_detect / done, stats.time_tracking_ms / done,
      stats.time_map_ms / done, stats.time_loop_ms / done,
      stats.time_optimize_ms + times.finish_ms);
  std::printf("outputs in %s/\n", out_dir.c_str());
}

class RunCommand : public Command {
 public:
  std::string Name() const override { return "run"; }
  std::string Summary() const override {
    return "Offline plane SLAM over a sequence (no SEQUENCE: the built-in synthetic room)";
  }
  int Order() const override { return 20; }

  void Setup(CLI::App& sub) override {
    sub.add_option("SEQUENCE", sequence_,
                   "TUM or ICL-NUIM folder, folder of organized .pcd, or KITTI .bin folder; "
                   "omitted: the synthetic scene of the 'simulation' config section");
    sub.add_option("-o,--out", out_dir_,
                   "output folder (default: output.directory, planeslam_out)");
    sub.add_option("--scene", scene_, "synthetic scene when no SEQUENCE: room, corridor, rubble");
    sub.add_option("--method", method_, "plane detector (default: detection.method)");
    AddSensorOption(sub, sensor_);
    AddConfigOptions(sub, options_);
    sub.footer(
        "Outputs: trajectory_tum.txt trajectory_kitti.txt plane_map.{ply,obj,json} pose_graph.g2o\n"
        "         octomap.bt (octomap.enabled) config.yaml summary.json frames.csv, and with "
        "ground truth metrics.json + "
        "plots/*.svg\n"
        "Ctrl-C stops after the current frame and writes the outputs of the frames done.\n"
        "A frame that cannot be read (corrupt, truncated or missing file) is left out with a "
        "warning\n"
        "(run.on_bad_frame: skip) or ends the run there (stop); a bad first frame is an error.\n"
        "Exit codes: 0 success; 2 error, nothing written; 5 completed with skipped frames;\n"
        "            6 stopped at a bad frame; 130 interrupted (5, 6, 130: outputs of the frames "
        "done).\n\n"
        "Examples:\n"
        "  planeslam run                                    synthetic room with loop closure\n"
        "  planeslam run --scene corridor --out corridor_out\n"
        "  planeslam run ../shared/data/tum_fr3_structure_notexture_far   (TUM fr3 profile, "
        "recognised)\n"
        "  planeslam run scans/ -c config/laser_scan.yaml --set octomap.enabled=false");
  }

  int Run() override {
    Config config = LoadConfigWithProfile(options_, sensor_, sequence_, "run");
    if (MaybePrintConfig(options_, config)) return 0;
    ApplyInputLimits(config);
    const RunConfig& run = config.Get<RunConfig>("run");
    const std::string method =
        method_.empty() ? config.Get<DetectionSection>("detection").method : method_;
    const std::string out_dir =
        out_dir_.empty() ? config.Get<OutputConfig>("output").directory : out_dir_;

    const RunInput input = OpenInput(sequence_, scene_, config);
    const std::unique_ptr<detection::PlaneDetector> detector =
        MakeDetector(method, config, run.decimation);
    const std::vector<std::size_t> indices = FrameIndices(input, run);
    const std::unique_ptr<mapping::SlamSystem> slam_system = MakeSlamSystem(config);
    mapping::SlamSystem& slam = *slam_system;
    if (run.start_at_ground_truth) {
      if (auto gt = input.sequence->GroundTruth(indices.front())) slam.SetInitialPose(*gt);
    }
    const mapping::OccupancyMapConfig& octomap_config =
        config.Get<mapping::OccupancyMapConfig>("octomap");
    const bool want_octomap = octomap_config.enabled && mapping::OccupancyMapBuilder::available();

    std::cerr << "planeslam run: " << input.name << ", " << indices.size() << " frames, detector "
              << detector->Name() << "\n";
    InstallInterruptHandlers();
    FrameLoopLog log;
    const auto wall_start = Clock::now();
    ProcessFrames(input, indices, run, *detector, want_octomap ? &octomap_config : nullptr,
                  options_.quiet, slam, &log);
    if (log.done == 0) {
      throw IoError(input.name, "interrupted before the first frame: nothing written");
    }

    FinishTimes times;
    auto t = Clock::now();
    const mapping::PoseGraphResult final_optimization = slam.Finish();
    times.finish_ms = MsSince(t);
    times.wall_seconds = std::chrono::duration<double>(Clock::now() - wall_start).count();

    // Everything is computed before the first file is written; each file is written atomically.
    t = Clock::now();
    EnsureDirectory(out_dir);
    const ds::Trajectory estimate = slam.EstimatedTrajectory();
    WriteMapOutputs(out_dir, slam, estimate, config, log);
    if (want_octomap) WriteOctomap(out_dir, octomap_config, slam, log);
    nlohmann::json metrics;
    std::string ate_line = "no ground truth";
    if (log.ground_truth.size() >= 3) {
      metrics = Score(log.ground_truth, estimate, run, out_dir);
      ate_line = AteLine(metrics);
    }
    times.write_ms = MsSince(t);
    nlohmann::json summary = SummaryJson(input.name, slam, final_optimization, log, times);
    if (!metrics.is_null()) summary["metrics"] = metrics;
    ds::WriteFileAtomic(out_dir + "/summary.json", summary.dump(2) + "\n");
    if (!metrics.is_null()) ds::WriteFileAtomic(out_dir + "/metrics.json", metrics.dump(2) + "\n");
    PrintReport(slam, log, times, ate_line, out_dir);
    if (log.interrupted) return kExitInterrupted;
    if (log.stopped_at_bad_frame) return kExitStoppedAtBadFrame;
    return log.bad_frames.empty() ? kExitSuccess : kExitSkippedFrames;
  }

 private:
  std::string sequence_;
  std::string out_dir_;
  std::string scene_;
  std::string method_;
  std::string sensor_;
  ConfigOptions options_;
};

PLANESLAM_REGISTER_COMMAND(RunCommand);

}  // namespace
}  // namespace planeslam::app

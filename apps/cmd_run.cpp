// `planeslam run [SEQUENCE]`: offline plane SLAM over a sequence (or the built-in synthetic room),
// writing the trajectory, the plane map, the pose graph, an optional OctoMap and, with ground
// truth, its own scores.
#include <malloc.h>
#include <unistd.h>

#include <chrono>
#include <exception>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "cli_common.hpp"
#include "command_registry.hpp"
#include "config_sections_app.hpp"
#include "config_sections_datasets.hpp"
#include "config_sections_slam.hpp"
#include "config_sections_synthetic.hpp"
#include "detector_factory.hpp"
#include "interrupt.hpp"
#include "pipeline.hpp"
#include "run_session.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "sensor_profiles.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;
using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
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

/// Records frame `index`, which the sequence could not read (`error`), in the session (frames.csv
/// row, warning). The first frame of the run has nothing to fall back on, so its error
/// propagates and nothing is written.
void RecordBad(const RunInput& input, std::size_t index, bool first, const RunConfig& run,
               RunSession& session, const IoError& error) {
  if (first) throw error;
  BadFrame bad{index, input.sequence->Timestamp(index), error.file(), error.what()};
  const bool stop = run.on_bad_frame == "stop";
  std::cerr << (::isatty(STDERR_FILENO) ? "\n" : "")
            << "planeslam run: " << (stop ? "error" : "warning") << ": frame " << index
            << (stop ? " stops the run" : " skipped") << ": " << bad.error << "\n";
  session.RecordBadFrame(std::move(bad), stop);
}

/// Loads each frame of `indices` and hands it to the session until done or interrupted, all on
/// this thread.
void ProcessFramesInline(const RunInput& input, const std::vector<std::size_t>& indices,
                         ProgressBar& progress, RunSession& session) {
  const RunConfig& run = session.run_config();
  for (std::size_t i : indices) {
    if (StopRequested()) {
      session.SetInterrupted();
      break;
    }
    const auto t = Clock::now();
    std::optional<ds::Frame> loaded;
    try {
      loaded = input.sequence->LoadDecimated(i, run.decimation);
    } catch (const IoError& e) {
      RecordBad(input, i, i == indices.front(), run, session, e);
    }
    session.AddLoadTime(MsSince(t));
    if (session.stopped_at_bad_frame()) break;
    if (!loaded) continue;
    session.Track(i, *loaded);
    progress.Update(session.frames_done());
  }
}

/// A frame read and detected ahead by a worker, or the reader's error.
struct FrameAhead {
  std::optional<PreparedFrame> prepared;
  std::exception_ptr load_error;  ///< an IoError from the sequence
  double load_ms = 0.0;
};

/// As ProcessFramesInline, with `workers` threads reading and detecting frames ahead (each with
/// its own detector; reading and detection depend on the frame alone) while this thread tracks
/// them in order. At most two frames per worker are held ahead.
void ProcessFramesAhead(const RunInput& input, const std::vector<std::size_t>& indices,
                        std::size_t workers, ProgressBar& progress, RunSession& session) {
  const RunConfig& run = session.run_config();
  std::vector<std::unique_ptr<detection::PlaneDetector>> detectors;
  for (std::size_t w = 0; w < workers; ++w) detectors.push_back(session.MakeWorkerDetector());
  auto produce = [&](std::size_t k, std::size_t worker) {
    FrameAhead ahead;
    const auto t = Clock::now();
    std::optional<ds::Frame> frame;
    try {
      frame = input.sequence->LoadDecimated(indices[k], run.decimation);
    } catch (const IoError&) {
      ahead.load_error = std::current_exception();
    }
    ahead.load_ms = MsSince(t);
    if (frame) ahead.prepared = session.Prepare(std::move(*frame), *detectors[worker]);
    return ahead;
  };
  OrderedPipeline<FrameAhead> pipeline(indices.size(), workers, 2 * workers, produce);
  for (std::size_t k = 0; k < indices.size(); ++k) {
    if (StopRequested()) {
      session.SetInterrupted();
      break;
    }
    FrameAhead ahead = pipeline.Take();
    session.AddLoadTime(ahead.load_ms);
    if (ahead.load_error) {
      try {
        std::rethrow_exception(ahead.load_error);
      } catch (const IoError& e) {
        RecordBad(input, indices[k], k == 0, run, session, e);
      }
    }
    if (session.stopped_at_bad_frame()) break;
    if (!ahead.prepared) continue;
    session.TrackPrepared(indices[k], *ahead.prepared);
    progress.Update(session.frames_done());
  }
}

/// Runs the frames inline on one thread, or ahead on session.threads() workers.
void ProcessFrames(const RunInput& input, const std::vector<std::size_t>& indices, bool quiet,
                   RunSession& session) {
  ProgressBar progress("run", indices.size(), quiet);
  const std::size_t threads = session.threads();
  if (threads <= 1 || indices.size() <= 1) {
    ProcessFramesInline(input, indices, progress, session);
  } else {
    ProcessFramesAhead(input, indices, threads, progress, session);
  }
  progress.Finish();
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
    sub.add_option("--scene", scene_,
                   "synthetic scene when no SEQUENCE: room, corridor, rubble, street, ring");
    sub.add_option("--method", method_, "plane detector (default: detection.method)");
    sub.add_option("--threads", threads_,
                   "threads (as run.threads; 0: the machine's cores); the outputs do not "
                   "depend on it")
        ->check(CLI::Range(0, 256));
    sub.add_flag("--no-report", no_report_, "do not write report.html (as report.enabled: false)");
    AddSensorOption(sub, sensor_);
    AddConfigOptions(sub, options_);
    sub.footer(
        "Outputs: trajectory_tum.txt trajectory_kitti.txt plane_map.{ply,obj,json} pose_graph.g2o\n"
        "         octomap.bt (octomap.enabled) config.yaml summary.json frames.csv, and with "
        "ground truth metrics.json + "
        "plots/*.svg\n"
        "         + ground_truth_tum.txt; report.html + keyframe_cloud.pcd (report.enabled, "
        "--no-report: off)\n"
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
    Config config = sequence_.empty() ? LoadConfigForScene(options_, sensor_, scene_, "run")
                                      : LoadConfigWithProfile(options_, sensor_, sequence_, "run");
    if (threads_) config.Get<RunConfig>("run").threads = *threads_;
    if (MaybePrintConfig(options_, config)) return 0;
    if (no_report_) config.Get<ReportConfig>("report").enabled = false;
    ApplyInputLimits(config);
    const RunConfig& run = config.Get<RunConfig>("run");
    const std::string method =
        method_.empty() ? config.Get<DetectionSection>("detection").method : method_;
    const std::string out_dir =
        out_dir_.empty() ? config.Get<OutputConfig>("output").directory : out_dir_;

    const RunInput input = OpenInput(sequence_, scene_, config);
    const std::vector<std::size_t> indices = FrameIndices(input, run);
    RunSession session(config, method, input.name);
    session.PlanRun(indices.size());
    if (run.start_at_ground_truth) {
      if (auto gt = input.sequence->GroundTruth(indices.front())) session.SetInitialPose(*gt);
    }

    std::cerr << "planeslam run: " << input.name << ", " << indices.size() << " frames, detector "
              << session.detector().Name() << "\n";
    InstallInterruptHandlers();
#ifdef __GLIBC__
    // glibc gives each worker thread its own malloc arena, which keeps the frame-sized buffers
    // that thread freed, so peak memory would grow with the thread count. One shared arena reuses
    // them; small blocks still come from the per-thread caches.
    if (session.threads() > 1) mallopt(M_ARENA_MAX, 1);
#endif
    ProcessFrames(input, indices, options_.quiet, session);
    if (session.frames_done() == 0) {
      throw IoError(input.name, "interrupted before the first frame: nothing written");
    }
    session.Finish();
    const std::string ate_line = session.Write(out_dir);
    session.PrintReport(ate_line, out_dir);
    session.WriteReport(out_dir);
    return session.ExitCode();
  }

 private:
  std::string sequence_;
  std::string out_dir_;
  std::string scene_;
  std::string method_;
  std::string sensor_;
  bool no_report_ = false;
  std::optional<int> threads_;
  ConfigOptions options_;
};

PLANESLAM_REGISTER_COMMAND(RunCommand);

}  // namespace
}  // namespace planeslam::app

#include "run_session.hpp"

#include <algorithm>
#include <cstdio>
#include <future>
#include <iostream>
#include <unordered_map>
#include <nlohmann/json.hpp>

#include "cli_common.hpp"
#include "closure_report.hpp"
#include "config_sections_app.hpp"
#include "config_sections_mapping.hpp"
#include "detector_factory.hpp"
#include "exit_codes.hpp"
#include "kitti_report.hpp"
#include "pipeline.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "planeslam/mapping/g2o_io.hpp"
#include "planeslam/mapping/map_writers.hpp"
#include "report.hpp"
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

/// One line of frames.csv.
void LogFrame(std::size_t index, double timestamp, const mapping::SlamFrameResult& result,
              std::ostringstream& log) {
  log << index << "," << ds::FormatRoundTrip(timestamp) << "," << result.keyframe << ","
      << result.planes << "," << result.matches << "," << result.tracked << "," << result.degenerate
      << "," << result.used_point_to_plane << "," << result.loop_closures << "," << result.refused
      << "," << result.closures_rejected << "," << result.closures_retracted << ",ok,"
      << result.constrained_by << "," << result.weak_directions << "\n";
}

/// The trajectory, plane map, pose graph, effective configuration and frame log.
void WriteMapOutputs(const std::string& out_dir, const mapping::SlamSystem& slam,
                     const ds::Trajectory& estimate, const Config& config,
                     const std::string& frame_log) {
  ds::WriteTumTrajectory(out_dir + "/trajectory_tum.txt", estimate);
  ds::WriteKittiTrajectory(out_dir + "/trajectory_kitti.txt", estimate);
  const auto records = mapping::MakeMapRecords(slam.map());
  mapping::WritePlaneMapPly(out_dir + "/plane_map.ply", records);
  mapping::WritePlaneMapObj(out_dir + "/plane_map.obj", records);
  mapping::WritePlaneMapJson(out_dir + "/plane_map.json", records);
  mapping::WriteG2o(slam.graph(), out_dir + "/pose_graph.g2o");
  ds::WriteFileAtomic(out_dir + "/config.yaml", config.ToYaml(true));
  ds::WriteFileAtomic(out_dir + "/frames.csv", frame_log);
}

/// The keyframes' thinned clouds inserted at their optimised poses, written as octomap.bt.
void WriteOctomap(
    const std::string& out_dir, const mapping::OccupancyMapConfig& config,
    const std::unordered_map<std::int64_t, Pose>& poses,
    const std::vector<std::pair<std::int64_t, std::vector<Eigen::Vector3f>>>& keyframe_clouds,
    unsigned threads) {
  mapping::OccupancyMapConfig thinned = config;
  thinned.downsample_voxel = 0.0;  // already thinned per keyframe
  mapping::OccupancyMapBuilder octomap(thinned);
  std::vector<const std::vector<Eigen::Vector3f>*> scans;
  std::vector<Pose> scan_poses;
  for (const auto& [id, points] : keyframe_clouds) {
    scans.push_back(&points);
    scan_poses.push_back(poses.at(id));
  }
  octomap.InsertAll(scans, scan_poses, threads);
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

nlohmann::json BadFramesJson(const std::vector<BadFrame>& bad_frames) {
  nlohmann::json list = nlohmann::json::array();
  for (const BadFrame& b : bad_frames) {
    list.push_back(
        {{"index", b.index}, {"timestamp", b.timestamp}, {"file", b.file}, {"error", b.error}});
  }
  return list;
}

}  // namespace

RunSession::RunSession(Config config, const std::string& method, std::string input_name)
    : config_(std::move(config)), input_name_(std::move(input_name)), method_(method) {
  detector_ = MakeDetector(method, config_, run_config().decimation);
  slam_ = MakeSlamSystem(config_);
  const auto& octomap = config_.Get<mapping::OccupancyMapConfig>("octomap");
  want_octomap_ = octomap.enabled && mapping::OccupancyMapBuilder::available();
  const auto& report = config_.Get<ReportConfig>("report");
  keep_keyframe_clouds_ = want_octomap_ || (report.enabled && report.cloud_points > 0);
  // Thinned at the sensor profile's voxel, which the OctoMap also uses (a LiDAR's is coarser
  // than a depth camera's): the report's cloud needs no more.
  keyframe_voxel_ = want_octomap_ || octomap.downsample_voxel > 0 ? octomap.downsample_voxel : 0.05;
  frame_log_ << "index,timestamp,keyframe,planes,matches,tracked,degenerate,point_to_plane,"
                "loop_closures,refused,closures_rejected,closures_retracted,status,constrained_by,weak_directions\n";
  wall_start_ = Clock::now();
}

RunSession::~RunSession() = default;

const RunConfig& RunSession::run_config() const { return config_.Get<RunConfig>("run"); }

void RunSession::PlanRun(std::size_t frames) { slam_->PlanRun(frames); }

void RunSession::SetInitialPose(const Pose& T_world_first) {
  slam_->SetInitialPose(T_world_first);
}

std::size_t RunSession::threads() const { return ResolveThreads(run_config().threads); }

std::unique_ptr<detection::PlaneDetector> RunSession::MakeWorkerDetector() const {
  return MakeDetector(method_, config_, run_config().decimation);
}

PreparedFrame RunSession::Prepare(ds::Frame frame, const detection::PlaneDetector& detector) const {
  const int decimation = run_config().decimation;
  const auto t = Clock::now();
  PreparedFrame prepared;
  // A frame loaded at the run's resolution (Sequence::LoadDecimated) is used as it is.
  PLANESLAM_CHECK(frame.decimation == 1 || frame.decimation == decimation,
                  "frame decimated by " << frame.decimation << ", run.decimation " << decimation);
  if (decimation > 1 && frame.decimation == 1) {
    frame.cloud = ds::Decimate(frame.cloud, decimation);
    frame.decimation = decimation;
  }
  prepared.segmentation = detector.Detect(frame.cloud);
  prepared.detect_ms = MsSince(t);
  prepared.frame = std::move(frame);
  return prepared;
}

mapping::SlamFrameResult RunSession::Track(std::size_t index, ds::Frame& frame) {
  PreparedFrame prepared = Prepare(std::move(frame), *detector_);
  const mapping::SlamFrameResult result = TrackPrepared(index, prepared);
  frame = std::move(prepared.frame);
  return result;
}

mapping::SlamFrameResult RunSession::TrackPrepared(std::size_t index, PreparedFrame& prepared) {
  const ds::Frame& frame = prepared.frame;
  time_detect_ += prepared.detect_ms;
  const mapping::SlamFrameResult result =
      slam_->ProcessFrame(frame.timestamp, frame.cloud, prepared.segmentation);
  if (frame.T_world_sensor_gt) ground_truth_.Add(frame.timestamp, *frame.T_world_sensor_gt);
  LogFrame(index, frame.timestamp, result, frame_log_);
  if (keep_keyframe_clouds_ && result.keyframe) {
    keyframe_clouds_.emplace_back(static_cast<std::int64_t>(slam_->stats().keyframes - 1),
                                  mapping::VoxelDownsample(frame.cloud.points, keyframe_voxel_));
    keyframe_clouds_.back().second.shrink_to_fit();  // kept for the whole run
  }
  ++done_;
  return result;
}

void RunSession::RecordBadFrame(BadFrame bad, bool stop) {
  frame_log_ << bad.index << "," << ds::FormatRoundTrip(bad.timestamp) << ",,,,,,,,,,,"
             << (stop ? "stopped" : "skipped") << ",,\n";
  bad_frames_.push_back(std::move(bad));
  stopped_at_bad_frame_ = stop;
}

const mapping::PoseGraphResult& RunSession::Finish() {
  if (finished_) return final_optimization_;
  const auto t = Clock::now();
  final_optimization_ = slam_->Finish();
  finish_ms_ = MsSince(t);
  wall_seconds_ = std::chrono::duration<double>(Clock::now() - wall_start_).count();
  finished_ = true;
  return final_optimization_;
}

std::string RunSession::Write(const std::string& out_dir) {
  Finish();
  // Everything is computed before the first file is written; each file is written atomically.
  const auto t = Clock::now();
  EnsureDirectory(out_dir);
  std::vector<double> outliers;
  const ds::Trajectory estimate = slam_->EstimatedTrajectory(&outliers);
  // The OctoMap (ray casting every keyframe: the longest output) is built on its own thread from
  // copies of the poses while this one writes the rest; it reads nothing else that changes.
  std::future<void> octomap;
  if (want_octomap_) {
    auto job = [this, out_dir, poses = slam_->KeyframePoses(),
                octomap_config = config_.Get<mapping::OccupancyMapConfig>("octomap")] {
      WriteOctomap(out_dir, octomap_config, poses, keyframe_clouds_,
                   static_cast<unsigned>(threads()));
    };
    octomap = std::async(threads() > 1 ? std::launch::async : std::launch::deferred, job);
  }
  WriteMapOutputs(out_dir, *slam_, estimate, config_, frame_log_.str());
  WriteClosuresCsv(out_dir + "/closures.csv", *slam_, ground_truth_);
  if (!ground_truth_.empty()) {
    ds::WriteTumTrajectory(out_dir + "/ground_truth_tum.txt", ground_truth_);
  }
  nlohmann::json metrics;
  std::string ate_line = "no ground truth";
  if (ground_truth_.size() >= 3) {
    metrics = Score(ground_truth_, estimate, run_config(), out_dir);
    ate_line = AteLine(metrics);
    if (!metrics.contains("error")) {
      AddKittiErrors(input_name_, ground_truth_, estimate, &metrics, &ate_line);
    }
  }
  if (octomap.valid()) octomap.get();
  write_ms_ = MsSince(t);
  const mapping::SlamStats& stats = slam_->stats();
  nlohmann::json summary = {
      {"input", input_name_},
      {"frames", done_},
      {"interrupted", interrupted_},
      {"skipped_frames", stopped_at_bad_frame_ ? 0 : bad_frames_.size()},
      {"stopped_at_bad_frame", stopped_at_bad_frame_},
      {"bad_frames", BadFramesJson(bad_frames_)},
      {"keyframes", stats.keyframes},
      {"loop_closures", stats.loop_closures},
      {"loop_candidates", stats.loop_candidates},
      {"loop_refused",
       {{"degenerate", stats.loop_refused_degenerate},
        {"matches", stats.loop_refused_matches},
        {"residual", stats.loop_refused_residual},
        {"ambiguous", stats.loop_refused_ambiguous}}},
      {"refused_frames", stats.refused_frames},
      {"degenerate_frames", stats.degenerate_frames},
      {"point_to_plane_frames", stats.point_to_plane_frames},
      {"prior_frames", stats.prior_frames},
      {"untracked_frames", stats.untracked_frames},
      {"outlier_frames", {{"count", outliers.size()}, {"timestamps", outliers}}},
      {"map_planes", slam_->map().size()},
      {"final_optimization",
       {{"initial_cost", final_optimization_.initial_cost},
        {"final_cost", final_optimization_.final_cost},
        {"iterations", final_optimization_.iterations},
        {"converged", final_optimization_.converged}}},
      {"time_ms",
       {{"load", time_load_},
        {"detect", time_detect_},
        {"track", stats.time_tracking_ms},
        {"map", stats.time_map_ms},
        {"loop", stats.time_loop_ms},
        {"optimize", stats.time_optimize_ms + finish_ms_},
        {"write", write_ms_}}},
      {"frames_per_second", done_ / std::max(wall_seconds_, 1e-9)}};
  summary["closures"] = ClosuresJson(*slam_, ground_truth_);
  summary["back_end"] = BackEndJson(*slam_);
  if (!metrics.is_null()) summary["metrics"] = metrics;
  ds::WriteFileAtomic(out_dir + "/summary.json", summary.dump(2) + "\n");
  if (!metrics.is_null()) ds::WriteFileAtomic(out_dir + "/metrics.json", metrics.dump(2) + "\n");
  return ate_line;
}

void RunSession::PrintReport(const std::string& ate_line, const std::string& out_dir) const {
  const mapping::SlamStats& stats = slam_->stats();
  const std::size_t done = done_;
  const char* prefix = interrupted_ ? "INTERRUPTED: outputs cover the frames processed: "
                       : stopped_at_bad_frame_
                           ? "STOPPED AT A BAD FRAME: outputs cover the frames "
                             "before it: "
                           : "";
  std::printf("%s%zu frames (%.1f frames/s), %zu keyframes, %zu loop closures, %zu map planes\n",
              prefix, done, done / std::max(wall_seconds_, 1e-9), stats.keyframes,
              stats.loop_closures, slam_->map().size());
  std::printf(
      "degenerate frames %zu (filled by point-to-plane alignment: %zu), untracked frames %zu "
      "(refused by the prior gate: %zu), frames with a direction from the prior %zu\n",
      stats.degenerate_frames, stats.point_to_plane_frames, stats.untracked_frames,
      stats.refused_frames, stats.prior_frames);
  std::printf(
      "loop candidates %zu, refused: degenerate %zu, few matches %zu, residual %zu, ambiguous %zu\n",
      stats.loop_candidates, stats.loop_refused_degenerate, stats.loop_refused_matches,
      stats.loop_refused_residual, stats.loop_refused_ambiguous);
  std::printf("closure hypotheses %zu: accepted %zu, rejected %zu, retracted %zu (closures.csv)\n",
              slam_->closures().size(), stats.loop_closures, stats.closures_rejected,
              stats.closures_retracted);
  if (!bad_frames_.empty() && !stopped_at_bad_frame_) {
    std::printf("SKIPPED %zu unreadable frame(s):", bad_frames_.size());
    for (const BadFrame& b : bad_frames_) std::printf(" %zu", b.index);
    std::printf(" (see summary.json)\n");
  }
  std::printf("%s\n", ate_line.c_str());
  std::printf(
      "time per frame [ms]: load %.2f detect %.2f track %.2f map %.2f loop %.2f; "
      "optimise %.1f ms total\n",
      time_load_ / done, time_detect_ / done, stats.time_tracking_ms / done,
      stats.time_map_ms / done, stats.time_loop_ms / done, stats.time_optimize_ms + finish_ms_);
  std::printf("outputs in %s/\n", out_dir.c_str());
}

void RunSession::WriteReport(const std::string& out_dir) const {
  const auto& report = config_.Get<ReportConfig>("report");
  if (!report.enabled) return;
  if (!ReportAvailable()) {
    std::cerr << "planeslam run: " << ReportUnavailableReason() << "\n";
    return;
  }
  const auto t = Clock::now();
  try {
    const auto max_points = static_cast<std::size_t>(report.cloud_points);
    if (max_points > 0 && !keyframe_clouds_.empty()) {
      WriteKeyframeCloud(out_dir + "/keyframe_cloud.pcd", keyframe_clouds_, slam_->KeyframePoses(),
                         max_points);
    }
    WriteRunReport(out_dir, max_points);
    std::printf("report.html written in %.0f ms\n", MsSince(t));
  } catch (const std::exception& e) {
    std::cerr << "planeslam run: warning: report.html not written: " << e.what() << "\n";
  }
}

int RunSession::ExitCode() const {
  if (interrupted_) return kExitInterrupted;
  if (stopped_at_bad_frame_) return kExitStoppedAtBadFrame;
  return bad_frames_.empty() ? kExitSuccess : kExitSkippedFrames;
}

}  // namespace planeslam::app

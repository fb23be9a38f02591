#pragma once
/// The frame-by-frame core of `planeslam run`: detector and SLAM system built from the
/// configuration, frames fed one at a time, then the final optimisation and every output file.
/// `planeslam run` drives it from a sequence; the Python module's Slam drives it from arrays, so
/// both give the same trajectory and the same files.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "config.hpp"
#include "config_sections_slam.hpp"
#include "planeslam/datasets/sequence.hpp"
#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/detection/plane_detector.hpp"
#include "planeslam/mapping/occupancy_map.hpp"
#include "planeslam/mapping/slam_system.hpp"

namespace planeslam::app {

/// A frame the sequence could not read: where it is and the reader's one-line error.
struct BadFrame {
  std::size_t index = 0;
  double timestamp = 0.0;  ///< [s] from the frame list
  std::string file;        ///< the file the error names
  std::string error;       ///< the reader's message, "FILE: reason"
};

/// A frame decimated (run.decimation) and segmented, ready to be tracked. Preparing is pure (it
/// depends on the frame alone), so `planeslam run` prepares frames ahead on worker threads.
struct PreparedFrame {
  datasets::Frame frame;
  detection::Segmentation segmentation;
  double detect_ms = 0.0;  ///< [ms] decimation and detection
};

class RunSession {
 public:
  /// `config`: the effective configuration (profile, files, overrides applied); `method`: the
  /// detector (MakeDetector); `input_name`: how summary.json names the input. Throws ConfigError
  /// on an unknown method or invalid parameters.
  RunSession(Config config, const std::string& method, std::string input_name);
  ~RunSession();
  RunSession(const RunSession&) = delete;
  RunSession& operator=(const RunSession&) = delete;

  const Config& config() const { return config_; }
  const RunConfig& run_config() const;
  const detection::PlaneDetector& detector() const { return *detector_; }
  const mapping::SlamSystem& slam() const { return *slam_; }

  /// Pose of the first frame in the world; call before the first Track.
  void SetInitialPose(const Pose& T_world_first);
  /// Number of frames the run will have (places the test hook's injected false closures).
  void PlanRun(std::size_t frames);

  /// Decimates (run.decimation), detects and tracks one frame; records it in frames.csv, keeps
  /// its ground-truth pose for the scores and, for a keyframe, its thinned cloud for the OctoMap.
  /// `index` is the frame's position in its sequence (frames.csv).
  mapping::SlamFrameResult Track(std::size_t index, datasets::Frame& frame);
  /// Track's first half: decimation and detection with `detector` (the session's, or one from
  /// MakeWorkerDetector for another thread). Reads only the configuration: safe to call from
  /// several threads at once, each with its own detector.
  PreparedFrame Prepare(datasets::Frame frame, const detection::PlaneDetector& detector) const;
  /// A detector configured as the session's, for a worker thread.
  std::unique_ptr<detection::PlaneDetector> MakeWorkerDetector() const;
  /// Track's second half, in frame order: tracking, mapping and the records.
  mapping::SlamFrameResult TrackPrepared(std::size_t index, PreparedFrame& prepared);
  /// Threads of the run (run.threads; 0 there = the machine's cores).
  std::size_t threads() const;
  /// A frame that could not be read: a frames.csv row and a summary.json entry; `stop` when it
  /// ended the run.
  void RecordBadFrame(BadFrame bad, bool stop);
  /// Adds the time spent reading a frame [ms] to the summary's load time.
  void AddLoadTime(double ms) { time_load_ += ms; }
  /// The run was interrupted (SIGINT/SIGTERM): the summary says so.
  void SetInterrupted() { interrupted_ = true; }

  std::size_t frames_done() const { return done_; }
  bool interrupted() const { return interrupted_; }
  bool stopped_at_bad_frame() const { return stopped_at_bad_frame_; }
  const std::vector<BadFrame>& bad_frames() const { return bad_frames_; }
  bool finished() const { return finished_; }

  /// The final optimisation; later calls return the first result.
  const mapping::PoseGraphResult& Finish();
  /// Writes every output of `planeslam run` into `out_dir` (created): trajectories, plane map,
  /// pose graph, OctoMap (octomap.enabled), config.yaml, frames.csv, summary.json and, with at
  /// least three ground-truth poses, metrics.json and plots. Finishes first when not finished.
  /// Returns the ATE line of the report ("no ground truth" without one).
  std::string Write(const std::string& out_dir);
  /// The report `planeslam run` prints to stdout.
  void PrintReport(const std::string& ate_line, const std::string& out_dir) const;
  /// keyframe_cloud.pcd and report.html (report.enabled) from the files Write wrote, with the
  /// time taken on stdout; a failure there leaves the other outputs standing and is a warning.
  void WriteReport(const std::string& out_dir) const;
  /// kExitSuccess, or the exit code for skipped frames, a stop at a bad frame or an interrupt.
  int ExitCode() const;

 private:
  Config config_;
  std::string input_name_;
  std::string method_;
  std::unique_ptr<detection::PlaneDetector> detector_;
  std::unique_ptr<mapping::SlamSystem> slam_;
  bool want_octomap_ = false;
  bool keep_keyframe_clouds_ = false;  ///< for the OctoMap or the report's point cloud
  double keyframe_voxel_ = 0.0;        ///< [m] their voxel grid

  std::size_t done_ = 0;
  bool interrupted_ = false;
  bool stopped_at_bad_frame_ = false;
  std::vector<BadFrame> bad_frames_;
  double time_load_ = 0.0, time_detect_ = 0.0;  ///< [ms] summed over the frames
  /// Thinned clouds of the keyframes by keyframe id, inserted into the OctoMap and the report's
  /// cloud at the end with the optimised keyframe poses.
  std::vector<std::pair<std::int64_t, std::vector<Eigen::Vector3f>>> keyframe_clouds_;
  datasets::Trajectory ground_truth_;
  std::ostringstream frame_log_;  ///< frames.csv: what the tracker did with each frame

  bool finished_ = false;
  mapping::PoseGraphResult final_optimization_;
  double finish_ms_ = 0.0, write_ms_ = 0.0, wall_seconds_ = 0.0;
  std::chrono::steady_clock::time_point wall_start_;
};

}  // namespace planeslam::app

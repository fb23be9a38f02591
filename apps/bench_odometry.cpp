#include "bench_odometry.hpp"
#include "exit_codes.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include "bench_common.hpp"
#include "cli_common.hpp"
#include "config_sections_registration.hpp"
#include "detector_factory.hpp"
#include "interrupt.hpp"
#include "kitti_report.hpp"
#include "pipeline.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "planeslam/registration/local_map.hpp"
#include "planeslam/registration/plane_odometry.hpp"
#ifdef PLANESLAM_HAVE_PCL_BASELINES
#include "pcl/baselines.hpp"
#endif

namespace planeslam::app::bench {
namespace {

namespace ds = planeslam::datasets;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

/// Drift over the whole run (DriftOverRun): the error in world axes [m] and the length of the
/// ground-truth path [m].
struct EndPointDrift {
  Eigen::Vector3d error = Eigen::Vector3d::Zero();
  double path_length = 0.0;
};

/// One method's run over the sequence.
struct OdometryRun {
  std::string name;
  ds::Trajectory trajectory;     ///< T_world_sensor per frame, first frame at its ground truth
  std::vector<double> times_ms;  ///< per frame after the first
  std::vector<Pose> motions;     ///< T_prev_curr per frame after the first
  int failures = 0;              ///< frames where the method fell back to the prior
  ds::RpeResult rpe_frame, rpe_second;
  bool evaluated = false;
  EndPointDrift drift;  ///< set when there are two or more frames with ground truth
  std::optional<ds::KittiOdometryResult> kitti;  ///< KITTI segment errors (KITTI ground truth)
};

/// What the plane registration said of the directions it could not see (ours only).
struct DegeneracyReport {
  int frames = 0;                  ///< frames with some undetermined direction
  int filled_icp = 0;              ///< of those, filled by point-to-plane alignment
  int filled_prior = 0;            ///< of those, filled (in part) from the constant-velocity prior
  int translation_directions = 0;  ///< undetermined translation axes over all frames
  Eigen::Vector3d abs_world_axis_sum = Eigen::Vector3d::Zero();  ///< sum of their |axis|, world
  /// Per frame after the first: what constrained it (registration::ConstraintSource) and how
  /// many directions the planes left open.
  std::vector<std::string> sources;
  std::vector<int> weak_directions;
  int translation_from_prior = 0;  ///< frames with a translation direction left to the prior

  void Add(const registration::OdometryStep& step, const Pose& T_world_prev) {
    const registration::RegistrationResult& r = step.registration;
    if (step.first_frame) return;
    sources.push_back(registration::ConstraintSource(r));
    weak_directions.push_back(static_cast<int>(r.degenerate_directions.size()));
    if (!r.degenerate) return;
    ++frames;
    filled_icp += r.used_icp ? 1 : 0;
    filled_prior += r.used_prior ? 1 : 0;
    translation_from_prior += r.prior_translations > 0 ? 1 : 0;
    for (const registration::Vector6d& d : r.degenerate_directions) {
      if (d.head<3>().norm() < 0.5) continue;  // a rotation axis
      ++translation_directions;
      abs_world_axis_sum += (T_world_prev.linear() * d.head<3>()).cwiseAbs();
    }
  }
};

/// The relative pose error between the first and the last frame with ground truth,
/// E = (G_a^-1 G_b)^-1 (P_a^-1 P_b), its translation turned into the world axes by G_b, and the
/// length of the ground-truth path between them. `ground_truth` holds the frames' own poses, so
/// its stamps are the estimate's.
EndPointDrift DriftOverRun(const ds::Trajectory& ground_truth, const ds::Trajectory& estimate) {
  EndPointDrift drift;
  if (ground_truth.size() < 2) return drift;
  auto find = [&](double stamp) -> const Pose* {
    for (std::size_t i = 0; i < estimate.size(); ++i) {
      if (estimate.stamps[i] == stamp) return &estimate.poses[i];
    }
    return nullptr;
  };
  const Pose* Pa = find(ground_truth.stamps.front());
  const Pose* Pb = find(ground_truth.stamps.back());
  if (Pa == nullptr || Pb == nullptr) return drift;
  const Pose& Ga = ground_truth.poses.front();
  const Pose& Gb = ground_truth.poses.back();
  const Pose E = (Ga.inverse() * Gb).inverse() * (Pa->inverse() * *Pb);
  drift.error = Gb.linear() * E.translation();
  for (std::size_t i = 1; i < ground_truth.size(); ++i) {
    drift.path_length +=
        (ground_truth.poses[i].translation() - ground_truth.poses[i - 1].translation()).norm();
  }
  return drift;
}

/// evo RPE (E = inv(Q_i^-1 Q_j) (P_i^-1 P_j), nearest-stamp association within 10 ms).
ds::RpeResult Rpe(const ds::Trajectory& gt, const ds::Trajectory& est, int delta_frames,
                  bool all_pairs) {
  ds::RpeOptions o;
  o.delta = delta_frames;
  o.delta_unit = ds::DeltaUnit::kFrames;
  o.all_pairs = all_pairs;
  return ds::EvaluateRpe(gt, est, o, "ground truth", "estimate");
}

/// Our odometry: the detector and registration::PlaneOdometry (frame-to-frame plane association
/// and registration with the constant-velocity prior, point-to-plane fill of degenerate
/// directions).
struct PlaneMethod {
  registration::PlaneOdometryConfig config;
  std::unique_ptr<detection::PlaneDetector> detector;
};

PlaneMethod MakePlaneMethod(const Config& config, const OdometryOptions& options) {
  PlaneMethod ours;
  const std::string method =
      options.method.empty() ? config.Get<DetectionSection>("detection").method : options.method;
  ours.config = OdometryConfigFrom(config);
  ours.detector = MakeDetector(method, config, ours.config.decimation);
  return ours;
}

#ifdef PLANESLAM_HAVE_PCL_BASELINES
pcl_baselines::GicpConfig GicpConfigFrom(const OdometryOptions& options) {
  pcl_baselines::GicpConfig gicp_config;
  gicp_config.voxel_size = options.gicp_voxel;
  gicp_config.max_correspondence_distance = options.gicp_max_distance;
  return gicp_config;
}
#endif

/// Every method's run over the sequence, and the frames' own ground-truth poses.
struct BenchRuns {
  OdometryRun ours;
  DegeneracyReport degeneracy;  ///< of ours
#ifdef PLANESLAM_HAVE_PCL_BASELINES
  OdometryRun pcl;
#endif
  ds::Trajectory ground_truth;

  /// Ours first, then the baseline when built.
  std::vector<OdometryRun*> All() {
    std::vector<OdometryRun*> runs = {&ours};
#ifdef PLANESLAM_HAVE_PCL_BASELINES
    runs.push_back(&pcl);
#endif
    return runs;
  }
  std::vector<const OdometryRun*> All() const {
    std::vector<const OdometryRun*> runs = {&ours};
#ifdef PLANESLAM_HAVE_PCL_BASELINES
    runs.push_back(&pcl);
#endif
    return runs;
  }
};

/// Feeds the first `n` frames to every method, timing each. Returns false when interrupted.
bool TrackSequence(const ds::Sequence& sequence, std::size_t n, const PlaneMethod& method,
                   const OdometryOptions& options, BenchRuns* runs) {
  const std::optional<Pose> first_gt = sequence.GroundTruth(0);
  const Pose T_world_first = first_gt ? *first_gt : Pose::Identity();
  registration::PlaneOdometry odometry(method.config, T_world_first);
  runs->ours.name = "planes(" + method.detector->Name() + ")";
#ifdef PLANESLAM_HAVE_PCL_BASELINES
  pcl_baselines::GicpOdometry gicp(GicpConfigFrom(options));
  runs->pcl.name = "pcl_gicp";
  Pose T_world_gicp = T_world_first;
#endif

  ProgressBar progress("bench odometry", n, options.quiet);
  // The next frames are read on another thread while this one times the methods, one at a time.
  OrderedPipeline<ds::Frame> reader(n, 1, 2,
                                    [&](std::size_t k, std::size_t) { return sequence.Load(k); });
  for (std::size_t i = 0; i < n; ++i) {
    if (StopRequested()) return false;
    const ds::Frame frame = reader.Take();
    if (frame.T_world_sensor_gt) runs->ground_truth.Add(frame.timestamp, *frame.T_world_sensor_gt);

    const Pose T_world_prev = odometry.T_world_sensor();
    auto t = Clock::now();
    const registration::OdometryStep step_ours =
        odometry.Track(frame.timestamp, frame.cloud, *method.detector);
    const double ours_ms = MsSince(t);
    runs->degeneracy.Add(step_ours, T_world_prev);
    runs->ours.trajectory.Add(frame.timestamp, step_ours.T_world_sensor);
    if (i > 0) {
      runs->ours.times_ms.push_back(ours_ms);
      runs->ours.motions.push_back(step_ours.T_prev_curr);
      if (!step_ours.registration.converged) ++runs->ours.failures;
    }
#ifdef PLANESLAM_HAVE_PCL_BASELINES
    const pcl_baselines::GicpStep step = gicp.Track(frame.cloud);
    if (i > 0) {
      T_world_gicp = T_world_gicp * step.T_prev_curr;
      runs->pcl.times_ms.push_back(step.time_ms);
      runs->pcl.motions.push_back(step.T_prev_curr);
      if (!step.converged) ++runs->pcl.failures;
    }
    runs->pcl.trajectory.Add(frame.timestamp, T_world_gicp);
#endif
    progress.Update(i + 1);
  }
  progress.Finish();
  return true;
}

/// The median frame interval [s] of `trajectory` and the RPE delta of 1 s in frames (evo's RPE
/// has no time unit).
struct SecondInFrames {
  double dt = 0.0;
  int frames = 1;
};

SecondInFrames OneSecondDelta(const ds::Trajectory& trajectory) {
  std::vector<double> dts;
  for (std::size_t i = 1; i < trajectory.size(); ++i) {
    dts.push_back(trajectory.stamps[i] - trajectory.stamps[i - 1]);
  }
  SecondInFrames second;
  second.dt = Median(dts);
  second.frames = std::max(1, static_cast<int>(std::lround(1.0 / second.dt)));
  return second;
}

/// RPE at delta 1 frame (consecutive pairs) and 1 s (every pair, evo --all_pairs, as consecutive
/// non-overlapping pairs would leave ~8) against the full ground-truth file (mocap rate) when the
/// sequence has one, else against the frames' own poses.
void EvaluateRuns(const std::string& sequence_path, int second_frames, BenchRuns* runs) {
  ds::Trajectory reference = runs->ground_truth;
  const fs::path gt_file = fs::path(sequence_path) / "groundtruth.txt";
  if (fs::is_regular_file(gt_file)) reference = ds::ReadTumTrajectory(gt_file.string());
  if (reference.size() < 2 || runs->ground_truth.size() < 2) return;
  for (OdometryRun* run : runs->All()) {
    run->rpe_frame = Rpe(reference, run->trajectory, 1, false);
    run->rpe_second = Rpe(reference, run->trajectory, second_frames, true);
    run->evaluated = true;
  }
}

void PrintSetup(const std::string& sequence_path, std::size_t n, const SecondInFrames& second,
                const PlaneMethod& method, [[maybe_unused]] const OdometryOptions& options) {
  std::printf("bench odometry: %s, %zu frames, delta 1 s = %d frames (median dt %.4f s)\n",
              sequence_path.c_str(), n, second.frames, second.dt);
  std::printf(
      "ours: detector %s at 1/%d resolution + PlaneOdometry (frame to frame, constant-velocity "
      "prior)\n",
      method.detector->Name().c_str(), method.config.decimation);
#ifdef PLANESLAM_HAVE_PCL_BASELINES
  const pcl_baselines::GicpConfig gicp_config = GicpConfigFrom(options);
  std::printf("pcl_gicp: VoxelGrid %.3f m, max correspondence %.3f m, k=%d, %d iterations\n",
              gicp_config.voxel_size, gicp_config.max_correspondence_distance,
              gicp_config.correspondence_randomness, gicp_config.max_iterations);
#endif
}

void PrintTable(const std::vector<const OdometryRun*>& runs) {
  std::printf("\n%-16s %10s %9s %14s %14s %14s %14s\n", "method", "ms/frame", "failures",
              "RPE1f t rmse", "RPE1f r rmse", "RPE1s t rmse", "RPE1s r rmse");
  for (const OdometryRun* run : runs) {
    if (run->evaluated) {
      std::printf("%-16s %10.2f %9d %12.2fcm %11.3fdeg %12.2fcm %11.3fdeg\n", run->name.c_str(),
                  Median(run->times_ms), run->failures, 100.0 * run->rpe_frame.trans_stats.rmse,
                  run->rpe_frame.rot_stats_deg.rmse, 100.0 * run->rpe_second.trans_stats.rmse,
                  run->rpe_second.rot_stats_deg.rmse);
    } else {
      std::printf("%-16s %10.2f %9d %14s %14s %14s %14s\n", run->name.c_str(),
                  Median(run->times_ms), run->failures, "-", "-", "-", "-");
    }
  }
}

void PrintDegeneracy(const OdometryRun& ours, const DegeneracyReport& degeneracy, std::size_t n) {
  std::printf(
      "\n%s: degenerate on %d of %zu frames (%d filled by point-to-plane alignment, %d "
      "from the prior)",
      ours.name.c_str(), degeneracy.frames, n - 1, degeneracy.filled_icp, degeneracy.filled_prior);
  if (degeneracy.translation_directions > 0) {
    const Eigen::Vector3d axis = degeneracy.abs_world_axis_sum / degeneracy.translation_directions;
    std::printf("; mean |undetermined translation axis| in the world (%.2f, %.2f, %.2f)", axis.x(),
                axis.y(), axis.z());
  }
  std::printf("\n");
}

/// Sets every run's drift and prints it; false (nothing printed) without two ground-truth frames.
bool DriftOfRuns(BenchRuns* runs) {
  if (runs->ground_truth.size() < 2) return false;
  for (OdometryRun* run : runs->All())
    run->drift = DriftOverRun(runs->ground_truth, run->trajectory);
  std::printf(
      "drift from the first to the last frame with ground truth (relative pose error in world "
      "axes x y z [cm]) over %.2f m of path:\n",
      runs->ours.drift.path_length);
  for (const OdometryRun* run : runs->All()) {
    const Eigen::Vector3d e = 100.0 * run->drift.error;
    std::printf("  %-16s %8.2f %8.2f %8.2f\n", run->name.c_str(), e.x(), e.y(), e.z());
  }
  return true;
}

/// Per frame: the difference between our relative motion and the baseline's,
/// E = M_baseline^-1 M_ours, as translation [m] and rotation angle [deg].
struct MotionDifference {
  std::vector<double> translation, rotation_deg;
};

MotionDifference CompareMotions(const OdometryRun& ours, const OdometryRun& baseline) {
  MotionDifference diff;
  const std::size_t n = std::min(ours.motions.size(), baseline.motions.size());
  for (std::size_t i = 0; i < n; ++i) {
    const Pose E = baseline.motions[i].inverse() * ours.motions[i];
    diff.translation.push_back(E.translation().norm());
    diff.rotation_deg.push_back(Eigen::AngleAxisd(E.linear()).angle() * 180.0 / M_PI);
  }
  return diff;
}

/// What constrained our frames, and how far each frame's motion is from the baseline's.
void PrintConstraints(const DegeneracyReport& degeneracy, const MotionDifference* diff,
                      const char* baseline) {
  std::map<std::string, int> counts;
  for (const std::string& s : degeneracy.sources) ++counts[s];
  std::printf("constrained by:");
  for (const auto& [source, count] : counts) std::printf(" %s %d,", source.c_str(), count);
  std::printf(" translation from the prior on %d frames\n", degeneracy.translation_from_prior);
  if (diff == nullptr || diff->translation.empty()) return;
  int within = 0;
  for (std::size_t i = 0; i < diff->translation.size(); ++i) {
    within += diff->translation[i] <= 0.05 && diff->rotation_deg[i] <= 0.3 ? 1 : 0;
  }
  std::printf(
      "per-frame relative motion vs %s: max %.2f cm, %.3f deg; within 5 cm and 0.3 deg on %d of "
      "%zu frames\n",
      baseline, 100.0 * *std::max_element(diff->translation.begin(), diff->translation.end()),
      *std::max_element(diff->rotation_deg.begin(), diff->rotation_deg.end()), within,
      diff->translation.size());
}

/// DIR/frames.csv: per frame what constrained our motion and, with the baseline, the
/// difference from its motion.
void WriteFramesCsv(const std::string& path, const BenchRuns& runs, const MotionDifference* diff) {
  std::ostringstream csv;
  csv << "index,timestamp,constrained_by,weak_directions,"
      << "translation_vs_baseline_m,rotation_vs_baseline_deg\n";
  const DegeneracyReport& d = runs.degeneracy;
  for (std::size_t i = 0; i < d.sources.size(); ++i) {
    csv << i + 1 << "," << ds::FormatRoundTrip(runs.ours.trajectory.stamps[i + 1]) << ","
        << d.sources[i] << "," << d.weak_directions[i] << ",";
    if (diff != nullptr && i < diff->translation.size()) {
      csv << ds::FormatRoundTrip(diff->translation[i]) << ","
          << ds::FormatRoundTrip(diff->rotation_deg[i]);
    } else {
      csv << ",";
    }
    csv << "\n";
  }
  ds::WriteFileAtomic(path, csv.str());
}

/// KITTI's segment errors of every run when the sequence's ground truth is KITTI-style; prints
/// them (or why there are none) and says whether there are any.
bool KittiOfRuns(const std::string& sequence_path, BenchRuns* runs) {
  if (!HasKittiGroundTruth(sequence_path)) return false;
  bool any = false;
  for (OdometryRun* run : runs->All()) {
    run->kitti = KittiErrors(runs->ground_truth, run->trajectory);
    if (!run->kitti) continue;
    if (!run->kitti->ok) {
      std::printf("KITTI segment errors: %s\n", run->kitti->message.c_str());
      return false;
    }
    std::printf("\n%s: %s", run->name.c_str(),
                FormatKittiErrors(*run->kitti, runs->ground_truth.size()).c_str());
    any = true;
  }
  return any;
}

void PrintFooter(const std::vector<const OdometryRun*>& runs) {
  if (runs.size() == 2) {
    std::printf("\nspeed ratio (median ms pcl_gicp / ours): %.1fx\n",
                Median(runs[1]->times_ms) / Median(runs[0]->times_ms));
  }
  std::printf(
      "\nms/frame: median; ours = decimation + detection + PlaneOdometry, GICP = voxel grid + "
      "covariances + alignment.\nRPE with evo's semantics (E = inv(Q_i^-1 Q_j)(P_i^-1 P_j), "
      "association within 10 ms), translation and rotation rmse.\n");
}

void WriteTrajectories(const std::string& out_dir, const BenchRuns& runs) {
  EnsureDirectory(out_dir);
  ds::WriteTumTrajectory(out_dir + "/planes.txt", runs.ours.trajectory);
#ifdef PLANESLAM_HAVE_PCL_BASELINES
  ds::WriteTumTrajectory(out_dir + "/gicp.txt", runs.pcl.trajectory);
#endif
}

void WriteJson(const std::string& path, std::size_t n, int second_frames, bool have_drift,
               int decimation, const BenchRuns& runs, const MotionDifference* diff) {
  nlohmann::json out = nlohmann::json::array();
  for (const OdometryRun* run : runs.All()) {
    nlohmann::json j = {{"method", run->name},
                        {"frames", n},
                        {"median_ms", Median(run->times_ms)},
                        {"failures", run->failures}};
    if (run->evaluated) {
      j["rpe_1_frame"] = {{"trans_rmse_m", run->rpe_frame.trans_stats.rmse},
                          {"rot_rmse_deg", run->rpe_frame.rot_stats_deg.rmse},
                          {"pairs", run->rpe_frame.trans_stats.count}};
      j["rpe_1_s"] = {{"delta_frames", second_frames},
                      {"trans_rmse_m", run->rpe_second.trans_stats.rmse},
                      {"rot_rmse_deg", run->rpe_second.rot_stats_deg.rmse},
                      {"pairs", run->rpe_second.trans_stats.count}};
    }
    if (have_drift) {
      j["drift_world_m"] = {run->drift.error.x(), run->drift.error.y(), run->drift.error.z()};
      j["path_length_m"] = run->drift.path_length;
    }
    if (run->kitti && run->kitti->ok) j["kitti"] = KittiErrorsJson(*run->kitti);
    if (run == &runs.ours) {
      j["decimation"] = decimation;
      j["degenerate_frames"] = runs.degeneracy.frames;
      j["filled_by_point_to_plane"] = runs.degeneracy.filled_icp;
      j["filled_from_prior"] = runs.degeneracy.filled_prior;
      j["translation_from_prior_frames"] = runs.degeneracy.translation_from_prior;
      nlohmann::json sources = nlohmann::json::object();
      for (const std::string& source : runs.degeneracy.sources) {
        sources[source] = sources.value(source, 0) + 1;
      }
      j["constrained_by"] = sources;
      if (diff != nullptr && !diff->translation.empty()) {
        j["motion_vs_baseline"] = {{"translation_m", diff->translation},
                                   {"rotation_deg", diff->rotation_deg}};
      }
    }
    out.push_back(std::move(j));
  }
  ds::WriteFileAtomic(path, out.dump(2) + "\n");
}

}  // namespace

int RunOdometryBench(const std::string& sequence_path, const Config& config,
                     const OdometryOptions& options) {
  const auto sequence = ds::OpenSequence(sequence_path, config.Get<ds::SensorConfig>("sensor"));
  std::size_t n = sequence->Size();
  if (options.max_frames > 0) n = std::min<std::size_t>(n, options.max_frames);
  if (n < 2) throw IoError(sequence_path, "odometry needs at least two frames");
  const PlaneMethod ours = MakePlaneMethod(config, options);

  BenchRuns runs;
  if (!TrackSequence(*sequence, n, ours, options, &runs)) return kExitInterrupted;
  const SecondInFrames second = OneSecondDelta(runs.ours.trajectory);
  EvaluateRuns(sequence_path, second.frames, &runs);

  PrintSetup(sequence_path, n, second, ours, options);
  PrintTable(std::as_const(runs).All());
  PrintDegeneracy(runs.ours, runs.degeneracy, n);
  std::optional<MotionDifference> diff;
#ifdef PLANESLAM_HAVE_PCL_BASELINES
  diff = CompareMotions(runs.ours, runs.pcl);
#endif
  PrintConstraints(runs.degeneracy, diff ? &*diff : nullptr, "pcl_gicp");
  const bool have_drift = DriftOfRuns(&runs);
  KittiOfRuns(sequence_path, &runs);
  PrintFooter(std::as_const(runs).All());

  if (!options.out_dir.empty()) {
    WriteTrajectories(options.out_dir, runs);
    WriteFramesCsv(options.out_dir + "/frames.csv", runs, diff ? &*diff : nullptr);
  }
  if (!options.json_path.empty()) {
    WriteJson(options.json_path, n, second.frames, have_drift, ours.config.decimation, runs,
              diff ? &*diff : nullptr);
  }
  return 0;
}

}  // namespace planeslam::app::bench

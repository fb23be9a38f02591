// `planeslam bench detect|odometry`: speed and quality of our detectors and odometry against the
// in-process PCL baselines, on the same frames, in one process.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "exit_codes.hpp"
#include "bench_common.hpp"
#include "bench_io.hpp"
#include "bench_long_run.hpp"
#include "bench_odometry.hpp"
#include "bench_quality.hpp"
#include "cli_common.hpp"
#include "command_registry.hpp"
#include "interrupt.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "sensor_profiles.hpp"
#include "svg_plot.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;
using bench::BenchFrame;
using bench::Method;

using StageTimes = std::vector<std::pair<std::string, std::vector<double>>>;

/// The samples of `stage` in `stages`, appended (keeping first-seen order) when new.
std::vector<double>& StageSamples(StageTimes& stages, const std::string& stage) {
  for (auto& [name, samples] : stages) {
    if (name == stage) return samples;
  }
  return stages.emplace_back(stage, std::vector<double>()).second;
}

/// Timing of one method on one frame.
struct DetectRecord {
  std::string method;
  std::string frame;
  std::vector<double> times_ms;
  int planes = 0;
  double assigned = 0.0;
  std::size_t valid_points = 0;
  int width = 0, height = 0;
  double median_ms = 0.0, min_ms = 0.0;
  /// The detector's own stage times [ms] over the repetitions, in the detector's stage order.
  StageTimes stages_ms;
};

std::string Fmt(const char* format, double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), format, v);
  return buffer;
}

class BenchCommand : public Command {
 public:
  std::string Name() const override { return "bench"; }
  std::string Summary() const override {
    return "Speed and quality of our detectors/odometry against PCL baselines on the same frames";
  }
  int Order() const override { return 50; }

  void Setup(CLI::App& sub) override {
    sub.require_subcommand(1);
    detect_ = sub.add_subcommand("detect", "Plane detection: our methods vs PCL's OMPS");
    detect_->add_option("frames", frames_,
                        "depth PNG / organized PCD / KITTI .bin files, or sequence folders (every "
                        "--stride-th frame); default: the standard set under the data folder");
    detect_->add_option("--methods", methods_,
                        "comma-separated methods (default: all of ours and pcl_omps)");
    detect_->add_option("--repeat", repeat_, "detections per method and frame (median, min)")
        ->check(CLI::Range(1, 1000));
    detect_->add_option("--stride", stride_, "use every N-th frame of a sequence folder")
        ->check(CLI::Range(1, 1000000));
    detect_->add_option("--json", json_path_, "write one object per method and frame to FILE");
    detect_->add_option("--plot", plot_dir_,
                        "write SVG plots (time per frame per method, time vs planes) into DIR");
    detect_->add_flag("--quality", quality_,
                      "run the quality suite instead: synthetic room/rubble with ground-truth "
                      "labels (Hoover T=0.8) and TUM plane repeatability (k = 1, 5, 15)");
    detect_
        ->add_option("--quality-frames", quality_options_.synthetic_frames,
                     "--quality: frames per synthetic sequence")
        ->check(CLI::Range(1, 10000));
    detect_
        ->add_option("--quality-stride", quality_options_.tum_stride,
                     "--quality: TUM repeatability uses every N-th frame as frame i")
        ->check(CLI::Range(1, 10000));
    AddOmpsOptions(*detect_);
    AddSensorOption(*detect_, detect_sensor_);
    AddConfigOptions(*detect_, detect_config_);
    detect_->footer(
        "Times are wall-clock per detection, single thread, methods interleaved per repetition.\n"
        "For pcl_omps only PCL's normal estimation + segmentation is timed (conversion excluded),\n"
        "so the speed ratios are conservative. Ratio = median over frames of the per-frame ratio\n"
        "of median times (PCL / method).\n"
        "\nExamples:\n"
        "  planeslam bench detect                         default frame set, 5 repetitions\n"
        "  planeslam bench detect --methods grid,pcl_omps --repeat 11 --json bench.json\n"
        "  planeslam bench detect depth/1341836537.655691.png --repeat 1\n"
        "  planeslam bench detect --quality --json quality.json --plot plots/");

    odometry_ =
        sub.add_subcommand("odometry", "Frame-to-frame odometry: our plane odometry vs PCL GICP");
    odometry_->add_option("sequence", sequence_, "sequence folder (TUM layout with groundtruth)")
        ->required();
    odometry_->add_option("--out", odometry_options_.out_dir,
                          "write DIR/planes.txt and DIR/gicp.txt (TUM format)");
    odometry_->add_option("--method", odometry_options_.method,
                          "our plane detector (default: detection.method)");
    odometry_->add_option("--max-frames", odometry_options_.max_frames,
                          "use at most N frames (0 = all)");
    odometry_->add_option("--gicp-voxel", odometry_options_.gicp_voxel,
                          "GICP voxel grid leaf size [m]");
    odometry_->add_option("--gicp-max-distance", odometry_options_.gicp_max_distance,
                          "GICP max correspondence distance [m]");
    odometry_->add_option("--json", odometry_options_.json_path, "write the results as JSON");
    AddSensorOption(*odometry_, odometry_sensor_);
    AddConfigOptions(*odometry_, odometry_config_);
    odometry_->footer(
        "Both methods get the same frames and start from a constant-velocity guess; each is timed\n"
        "from the frame's cloud to its pose: ours decimates (odometry.decimation), detects and\n"
        "registers planes, GICP voxelizes, estimates covariances and aligns. RPE follows evo\n"
        "(E = inv(Q_i^-1 Q_j) (P_i^-1 P_j)) at delta 1 frame (consecutive pairs) and 1 s (all\n"
        "pairs). Also printed: on how many frames our planes left a direction undetermined and\n"
        "what filled it, and each method's drift from the first to the last frame.\n"
        "\nExample:\n"
        "  planeslam bench odometry ../shared/data/tum_fr3_structure_notexture_far --out odo/");
    long_run_ = sub.add_subcommand(
        "long-run", "Long runs and wrong loop closures: many-lap room, injected false closures, "
                    "the aliasing ring");
    long_run_->add_option("--laps", long_run_options_.laps, "laps of the long room runs");
    long_run_->add_option("--seeds", long_run_options_.seeds, "noise seeds of the long room runs");
    long_run_->add_option("--inject", long_run_options_.injected,
                          "false closures injected into the built-in room, one run each");
    long_run_->add_option("--json", long_run_options_.json_path, "write the results as JSON");
    AddConfigOptions(*long_run_, long_run_config_);
    io_ = sub.add_subcommand("io", "Input readers: PNG depth (libpng vs ours), KITTI .bin, PCD");
    io_->add_option("--data", io_options_.data_dir, "shared data folder (default: as the tests)");
    io_->add_option("--repeat", io_options_.repeat, "decodes per file, the median counts")
        ->check(CLI::Range(1, 1000));
    io_->add_option("--json", io_options_.json_path, "write the results as JSON");
  }

  int Run() override {
    if (detect_->parsed()) return quality_ ? RunQuality() : RunDetect();
    if (io_->parsed()) {
      if (io_options_.data_dir.empty()) io_options_.data_dir = bench::DataDir();
      return bench::RunIoBench(io_options_);
    }
    if (long_run_->parsed()) {
      long_run_options_.quiet = long_run_config_.quiet;
      return bench::RunLongRunBench(long_run_config_, long_run_options_);
    }
    return RunOdometry();
  }

 private:
  void AddOmpsOptions(CLI::App& app) {
    app.add_option("--omps-normals", omps_.normal_method,
                   "pcl_omps normals: covariance or average_3d_gradient")
        ->check(CLI::IsMember({"covariance", "average_3d_gradient"}));
    app.add_option("--omps-depth-change", omps_.max_depth_change_factor,
                   "pcl_omps IntegralImageNormalEstimation max depth change factor");
    app.add_option("--omps-smoothing", omps_.normal_smoothing_size,
                   "pcl_omps normal smoothing size [px]");
    app.add_option("--omps-min-inliers", omps_.min_inliers, "pcl_omps min region size [px]");
    app.add_option("--omps-angle", omps_.angular_threshold_deg, "pcl_omps angular threshold [deg]");
    app.add_option("--omps-distance", omps_.distance_threshold,
                   "pcl_omps distance threshold [m at 1 m, scaled by z^2]");
    app.add_option("--omps-curvature", omps_.maximum_curvature,
                   "pcl_omps maximum curvature (PCL default 0.001 rejects noisy Kinect planes)");
  }

  std::vector<std::string> MethodNames() const {
    std::vector<std::string> names = bench::SplitList(methods_);
    return names.empty() ? bench::AllMethods() : names;
  }

  int RunDetect() {
    const Config config = LoadConfigWithProfile(
        detect_config_, detect_sensor_, frames_.empty() ? "" : frames_.front(), "bench detect");
    if (MaybePrintConfig(detect_config_, config)) return 0;
    const auto& sensor = config.Get<ds::SensorConfig>("sensor");
    std::vector<std::string> skipped;
    const std::string data_dir = bench::DataDir();
    const std::vector<BenchFrame> frames =
        frames_.empty() ? bench::LoadDefaultFrames(data_dir, sensor, &skipped)
                        : bench::LoadFrames(frames_, sensor, stride_);
    for (const std::string& s : skipped)
      std::cerr << "planeslam: note: skipped missing " << s << "\n";
    if (frames.empty()) {
      throw IoError(data_dir, "no benchmark frames (set PLANESLAM_DATA_DIR or give FRAMES)");
    }
    const std::vector<Method> methods = bench::MakeMethods(MethodNames(), config, omps_);

    std::vector<DetectRecord> records;
    ProgressBar progress("bench detect", frames.size() * methods.size() * repeat_,
                         detect_config_.quiet);
    std::size_t done = 0;
    for (const BenchFrame& frame : frames) {
      std::vector<DetectRecord> per(methods.size());
      const std::size_t valid = frame.cloud.CountValid();
      // Interleave the methods within each repetition, so background load affects all alike.
      for (int r = 0; r < repeat_; ++r) {
        for (std::size_t m = 0; m < methods.size(); ++m) {
          if (StopRequested()) return kExitInterrupted;
          detection::Segmentation seg;
          per[m].times_ms.push_back(bench::TimedDetect(methods[m], frame.cloud, &seg));
          AddStageTimes(seg, per[m]);
          if (r == 0) {
            per[m].planes = static_cast<int>(seg.planes.size());
            per[m].assigned = bench::AssignedFraction(frame.cloud, seg);
          }
          progress.Update(++done);
        }
      }
      for (std::size_t m = 0; m < methods.size(); ++m) {
        DetectRecord& rec = per[m];
        rec.method = methods[m].name;
        rec.frame = frame.name;
        rec.valid_points = valid;
        rec.width = frame.cloud.width;
        rec.height = frame.cloud.height;
        rec.median_ms = bench::Median(rec.times_ms);
        rec.min_ms = *std::min_element(rec.times_ms.begin(), rec.times_ms.end());
        records.push_back(std::move(rec));
      }
    }
    progress.Finish();
    PrintDetect(frames, methods, records);
    if (!json_path_.empty()) WriteDetectJson(records);
    if (!plot_dir_.empty()) WriteDetectPlots(methods, records);
    return 0;
  }

  static void AddStageTimes(const detection::Segmentation& seg, DetectRecord& rec) {
    for (const auto& [stage, ms] : seg.timings_ms) StageSamples(rec.stages_ms, stage).push_back(ms);
  }

  /// A 640 x 480 frame: the Kinect-class frames the detection speed targets are stated for.
  static bool IsVgaFrame(const DetectRecord& r) { return r.width == 640 && r.height == 480; }

  /// Per-frame PCL/method ratio of median times, keyed by method; only of 640 x 480 frames when
  /// vga_only.
  std::map<std::string, std::vector<double>> Ratios(const std::vector<DetectRecord>& records,
                                                    bool vga_only = false) const {
    std::map<std::string, double> pcl;  // frame -> pcl median
    for (const auto& r : records) {
      if (r.method == "pcl_omps") pcl[r.frame] = r.median_ms;
    }
    std::map<std::string, std::vector<double>> ratios;
    for (const auto& r : records) {
      if (vga_only && !IsVgaFrame(r)) continue;
      auto it = pcl.find(r.frame);
      if (it != pcl.end() && r.median_ms > 0.0)
        ratios[r.method].push_back(it->second / r.median_ms);
    }
    return ratios;
  }

  void PrintDetect(const std::vector<BenchFrame>& frames, const std::vector<Method>& methods,
                   const std::vector<DetectRecord>& records) const {
    std::printf("bench detect: %zu frames, %d repetitions, single thread\n", frames.size(),
                repeat_);
    for (const Method& m : methods) {
      if (m.is_pcl) std::printf("pcl_omps settings: %s\n", omps_.Describe().c_str());
    }
    // Per-frame medians [ms] and planes, one column per method.
    std::printf("\n%-44s", "frame (median ms / planes)");
    for (const Method& m : methods) std::printf(" %16s", m.name.c_str());
    std::printf("\n");
    for (const BenchFrame& f : frames) {
      std::printf("%-44s", f.name.c_str());
      for (const Method& m : methods) {
        for (const auto& r : records) {
          if (r.frame == f.name && r.method == m.name) {
            std::printf(" %10.2f / %3d", r.median_ms, r.planes);
          }
        }
      }
      std::printf("\n");
    }
    const auto ratios = Ratios(records);
    const auto vga_ratios = Ratios(records, true);
    std::printf("\n%-12s %12s %12s %8s %10s %14s %16s %16s\n", "method", "median ms", "min ms",
                "planes", "assigned", "x PCL (med)", "x PCL (of med)", "x PCL (640x480)");
    double pcl_of_medians = std::nan("");
    std::map<std::string, double> median_of_medians;
    for (const Method& m : methods) {
      std::vector<double> med;
      for (const auto& r : records) {
        if (r.method == m.name) med.push_back(r.median_ms);
      }
      median_of_medians[m.name] = bench::Median(med);
      if (m.is_pcl) pcl_of_medians = median_of_medians[m.name];
    }
    for (const Method& m : methods) {
      std::vector<double> mins, planes, assigned;
      for (const auto& r : records) {
        if (r.method != m.name) continue;
        mins.push_back(r.min_ms);
        planes.push_back(r.planes);
        assigned.push_back(r.assigned);
      }
      const auto it = ratios.find(m.name);
      const double ratio = it == ratios.end() ? std::nan("") : bench::Median(it->second);
      const double of_medians = pcl_of_medians / median_of_medians[m.name];
      const auto vga = vga_ratios.find(m.name);
      const double vga_ratio = vga == vga_ratios.end() ? std::nan("") : bench::Median(vga->second);
      std::printf("%-12s %12.2f %12.2f %8.1f %9.1f%% %14s %16s %16s\n", m.name.c_str(),
                  median_of_medians[m.name], bench::Median(mins), bench::Median(planes),
                  100.0 * bench::Median(assigned),
                  std::isnan(ratio) ? "-" : Fmt("%.1fx", ratio).c_str(),
                  std::isnan(of_medians) ? "-" : Fmt("%.1fx", of_medians).c_str(),
                  std::isnan(vga_ratio) ? "-" : Fmt("%.1fx", vga_ratio).c_str());
    }
    // Where the time goes: per method, each stage's median over frames of its per-frame median.
    std::printf("\nstages (median over frames of the per-frame median ms):\n");
    for (const Method& m : methods) {
      StageTimes stages;
      for (const auto& r : records) {
        if (r.method != m.name) continue;
        for (const auto& [stage, times] : r.stages_ms) {
          StageSamples(stages, stage).push_back(bench::Median(times));
        }
      }
      std::printf("  %-12s", m.name.c_str());
      for (const auto& [stage, medians] : stages) {
        std::printf(" %s %.2f", stage.c_str(), bench::Median(medians));
      }
      std::printf("\n");
    }
    std::printf(
        "\nmedian ms = median over frames of each frame's median time; min ms = median over frames "
        "of each frame's fastest run;\nplanes, assigned = median over frames (assigned = share of "
        "valid points labelled);\nx PCL (med) = median over frames of (PCL median time / method "
        "median time) on the same frame;\nx PCL (of med) = ratio of the median-ms column;\nx PCL "
        "(640x480) = x PCL (med) over the 640 x 480 frames only (the Kinect-class frames; the "
        "laser scans are not).\n");
  }

  void WriteDetectJson(const std::vector<DetectRecord>& records) const {
    const auto ratios = Ratios(records);
    std::map<std::string, double> pcl;
    for (const auto& r : records) {
      if (r.method == "pcl_omps") pcl[r.frame] = r.median_ms;
    }
    nlohmann::json out = nlohmann::json::array();
    for (const auto& r : records) {
      nlohmann::json j = {{"method", r.method},
                          {"frame", r.frame},
                          {"median_ms", r.median_ms},
                          {"min_ms", r.min_ms},
                          {"times_ms", r.times_ms},
                          {"planes", r.planes},
                          {"assigned_fraction", r.assigned},
                          {"valid_points", r.valid_points},
                          {"width", r.width},
                          {"height", r.height}};
      const auto it = pcl.find(r.frame);
      if (it != pcl.end() && r.median_ms > 0.0) j["speedup_vs_pcl"] = it->second / r.median_ms;
      out.push_back(std::move(j));
    }
    ds::WriteFileAtomic(json_path_, out.dump(2) + "\n");
  }

  void WriteDetectPlots(const std::vector<Method>& methods,
                        const std::vector<DetectRecord>& records) const {
    std::vector<std::string> names;
    for (const Method& m : methods) names.push_back(m.name);
    std::vector<bench::TimingSample> samples;
    for (const auto& r : records) samples.push_back({r.method, r.median_ms, r.planes});
    bench::WriteTimePlots(plot_dir_, names, samples);
  }

  int RunQuality() {
    const Config config = LoadConfig(detect_config_);
    if (MaybePrintConfig(detect_config_, config)) return 0;
    const std::vector<Method> methods = bench::MakeMethods(MethodNames(), config, omps_);
    quality_options_.json_path = json_path_;
    quality_options_.plot_dir = plot_dir_;
    quality_options_.quiet = detect_config_.quiet;
    quality_options_.data_dir = bench::DataDir();
    for (const Method& m : methods) {
      if (m.is_pcl) std::printf("pcl_omps settings: %s\n", omps_.Describe().c_str());
    }
    return bench::RunQualitySuite(methods, config, quality_options_);
  }

  int RunOdometry() {
    const Config config =
        LoadConfigWithProfile(odometry_config_, odometry_sensor_, sequence_, "bench odometry");
    if (MaybePrintConfig(odometry_config_, config)) return 0;
    odometry_options_.quiet = odometry_config_.quiet;
    return bench::RunOdometryBench(sequence_, config, odometry_options_);
  }

  CLI::App* detect_ = nullptr;
  CLI::App* odometry_ = nullptr;
  CLI::App* long_run_ = nullptr;
  CLI::App* io_ = nullptr;
  bench::IoBenchOptions io_options_;
  bench::LongRunOptions long_run_options_;
  ConfigOptions long_run_config_;
  // detect
  std::vector<std::string> frames_;
  std::string methods_;
  int repeat_ = 5;
  int stride_ = 50;
  std::string json_path_;
  std::string plot_dir_;
  bool quality_ = false;
  bench::QualityOptions quality_options_;
  bench::OmpsSettings omps_;
  ConfigOptions detect_config_;
  std::string detect_sensor_;
  // odometry
  std::string sequence_;
  bench::OdometryOptions odometry_options_;
  ConfigOptions odometry_config_;
  std::string odometry_sensor_;
};

}  // namespace

PLANESLAM_REGISTER_COMMAND(BenchCommand);

}  // namespace planeslam::app

#include "bench_quality.hpp"
#include "exit_codes.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>

#include "cli_common.hpp"
#include "config_sections_synthetic.hpp"
#include "interrupt.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/plane_repeatability.hpp"
#include "planeslam/datasets/segmentation_metrics.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"
#include "svg_plot.hpp"

namespace planeslam::app::bench {
namespace {

namespace ds = planeslam::datasets;
namespace fs = std::filesystem;

/// Segmentation quality of one method on one synthetic sequence.
struct SegRow {
  std::string dataset;
  std::string method;
  std::vector<double> times_ms;
  ds::SegmentationSummary summary;
};

/// Repeatability of one method at one frame gap.
struct RepRow {
  std::string dataset;
  std::string method;
  int k = 0;
  std::vector<double> times_ms;
  ds::RepeatabilitySummary summary;
};

std::vector<std::size_t> EvenlySpread(std::size_t n, int count) {
  std::vector<std::size_t> ids;
  if (n == 0) return ids;
  const std::size_t c = std::min<std::size_t>(n, static_cast<std::size_t>(count));
  for (std::size_t i = 0; i < c; ++i) ids.push_back(i * n / c);
  return ids;
}

std::vector<ds::RepeatabilityPlane> ToRepeatability(const detection::Segmentation& seg) {
  std::vector<ds::RepeatabilityPlane> planes;
  for (const auto& p : seg.planes) planes.push_back({p.normal, p.d, p.point_count});
  return planes;
}

/// Everything the suite measured.
struct QualityResults {
  std::vector<SegRow> seg_rows;
  std::vector<RepRow> rep_rows;
  std::vector<TimingSample> samples;
};

/// A synthetic sequence of the suite: a scene seen by a sensor.
struct SyntheticCase {
  ds::SceneKind scene;
  std::string sensor;
};

/// The ground-truth normals of `scene` in the sensor frame of `frame`: n_s = R_world_sensor^T n_w.
std::vector<Eigen::Vector3d> SensorFrameNormals(const ds::SyntheticScene& scene,
                                                const ds::SyntheticFrame& frame) {
  const Eigen::Matrix3d R = frame.frame.T_world_sensor_gt->linear();
  std::vector<Eigen::Vector3d> normals;
  for (const auto& plane : scene.planes) normals.push_back(R.transpose() * plane.normal);
  return normals;
}

/// Segmentation quality of every method on one synthetic sequence with ground-truth labels and
/// planes, sensor noise on. Returns false when interrupted.
bool EvaluateSyntheticCase(const SyntheticCase& c, const std::vector<Method>& methods,
                           const Config& config, const QualityOptions& options,
                           QualityResults* results) {
  ds::SegmentationMetricsOptions metric_options;
  metric_options.tolerance = options.tolerance;
  metric_options.min_gt_pixels = options.min_gt_pixels;
  // The "simulation*" config sections apply (noise model, seed); sensor and noise are forced.
  ds::SyntheticConfig sc = MakeSyntheticConfig(ds::SceneName(c.scene), config);
  sc.sensor = c.sensor;
  sc.pinhole.noise = true;
  sc.spherical.noise = true;
  const ds::SyntheticSequence sequence(sc);
  const std::string dataset = ds::SceneName(c.scene) + "/" + c.sensor;
  std::vector<SegRow> rows(methods.size());
  for (std::size_t m = 0; m < methods.size(); ++m) {
    rows[m].dataset = dataset;
    rows[m].method = methods[m].name;
  }
  const auto ids = EvenlySpread(sequence.Size(), options.synthetic_frames);
  ProgressBar progress("quality " + dataset, ids.size(), options.quiet);
  std::size_t done = 0;
  for (const std::size_t i : ids) {
    if (StopRequested()) return false;
    const ds::SyntheticFrame frame = sequence.Generate(i);
    std::vector<std::int32_t> gt(frame.labels.data.begin(), frame.labels.data.end());
    const std::vector<Eigen::Vector3d> gt_normals = SensorFrameNormals(sequence.scene(), frame);
    for (std::size_t m = 0; m < methods.size(); ++m) {
      detection::Segmentation seg;
      const double ms = TimedDetect(methods[m], frame.frame.cloud, &seg);
      std::vector<Eigen::Vector3d> det_normals;
      for (const auto& p : seg.planes) det_normals.push_back(p.normal);
      rows[m].summary.Add(
          ds::EvaluateSegmentation(gt, seg.labels, gt_normals, det_normals, metric_options));
      rows[m].times_ms.push_back(ms);
      results->samples.push_back({methods[m].name, ms, static_cast<int>(seg.planes.size())});
    }
    progress.Update(++done);
  }
  progress.Finish();
  for (auto& r : rows) results->seg_rows.push_back(std::move(r));
  return true;
}

/// The frames the repeatability pairs need: every i on the stride and i + k for each k, where both
/// have ground truth.
std::map<std::size_t, bool> RepeatabilityFrames(const ds::Sequence& sequence,
                                                const QualityOptions& options) {
  const std::size_t n = sequence.Size();
  std::map<std::size_t, bool> needed;
  for (std::size_t i = 0; i < n; i += static_cast<std::size_t>(options.tum_stride)) {
    for (const int k : options.tum_k) {
      const std::size_t j = i + static_cast<std::size_t>(k);
      if (j < n && sequence.GroundTruth(i) && sequence.GroundTruth(j)) {
        needed[i] = needed[j] = true;
      }
    }
  }
  return needed;
}

/// One method's planes and detection time per frame index.
struct DetectedFrames {
  std::map<std::size_t, std::vector<ds::RepeatabilityPlane>> planes;
  std::map<std::size_t, double> times;
};

/// The repeatability row of one method at frame gap k: its planes of frame i + k mapped into frame
/// i with the ground-truth relative pose, matched against those of frame i.
RepRow RepeatabilityRow(const ds::Sequence& sequence, const std::string& method, int k,
                        const DetectedFrames& detected, const QualityOptions& options) {
  ds::RepeatabilityOptions rep_options;
  rep_options.large_pixels = options.repeat_large_pixels;
  const std::size_t n = sequence.Size();
  RepRow row;
  row.dataset = "tum k=" + std::to_string(k);
  row.method = method;
  row.k = k;
  for (std::size_t i = 0; i < n; i += static_cast<std::size_t>(options.tum_stride)) {
    const std::size_t j = i + static_cast<std::size_t>(k);
    if (j >= n || !detected.planes.count(i) || !detected.planes.count(j)) continue;
    const auto gi = sequence.GroundTruth(i);
    const auto gj = sequence.GroundTruth(j);
    if (!gi || !gj) continue;
    const Pose T_i_j = gi->inverse() * *gj;
    row.summary.Add(
        ds::MatchPlanes(detected.planes.at(i), detected.planes.at(j), T_i_j, rep_options));
  }
  for (const auto& [index, ms] : detected.times) row.times_ms.push_back(ms);
  return row;
}

/// TUM repeatability with the ground-truth relative poses; each needed frame is detected once per
/// method. Returns false when interrupted.
bool EvaluateTumRepeatability(const fs::path& tum, const std::vector<Method>& methods,
                              const Config& config, const QualityOptions& options,
                              QualityResults* results) {
  const auto& sensor = config.Get<ds::SensorConfig>("sensor");
  const auto sequence = ds::OpenSequence(tum.string(), sensor);
  const std::map<std::size_t, bool> needed = RepeatabilityFrames(*sequence, options);
  std::vector<DetectedFrames> detected(methods.size());
  ProgressBar progress("quality tum", needed.size(), options.quiet);
  std::size_t done = 0;
  for (const auto& [index, unused] : needed) {
    if (StopRequested()) return false;
    const ds::Frame frame = sequence->Load(index);
    for (std::size_t m = 0; m < methods.size(); ++m) {
      detection::Segmentation seg;
      const double ms = TimedDetect(methods[m], frame.cloud, &seg);
      detected[m].planes[index] = ToRepeatability(seg);
      detected[m].times[index] = ms;
      results->samples.push_back({methods[m].name, ms, static_cast<int>(seg.planes.size())});
    }
    progress.Update(++done);
  }
  progress.Finish();
  for (const int k : options.tum_k) {
    for (std::size_t m = 0; m < methods.size(); ++m) {
      results->rep_rows.push_back(
          RepeatabilityRow(*sequence, methods[m].name, k, detected[m], options));
    }
  }
  return true;
}

void PrintQualityTables(const QualityOptions& options, const QualityResults& results) {
  std::printf(
      "\nbench detect --quality: Hoover T=%.2f on ground-truth planes >= %lld px, %d frames per "
      "synthetic sequence (sensor noise on);\nTUM repeatability on every %d-th frame, planes >= "
      "%lld px must find a partner (gates 10 deg, 10 cm)\n\n",
      options.tolerance, static_cast<long long>(options.min_gt_pixels), options.synthetic_frames,
      options.tum_stride, static_cast<long long>(options.repeat_large_pixels));
  std::printf("%-18s %-10s %8s %8s %7s %7s %7s %7s %8s %8s %6s %6s\n", "dataset", "method",
              "ms/frame", "correct", "over/f", "under/f", "miss/f", "noise/f", "ang mean",
              "ang max", "F1", "pixacc");
  for (const SegRow& r : results.seg_rows) {
    const auto& s = r.summary;
    const double f = s.frames ? double(s.frames) : 1.0;
    std::printf("%-18s %-10s %8.2f %7.1f%% %7.2f %7.2f %7.2f %7.2f %8.3f %8.3f %6.3f %6.3f\n",
                r.dataset.c_str(), r.method.c_str(), Median(r.times_ms), 100.0 * s.CorrectRate(),
                s.over_large / f, s.under_segmented / f, s.missed_large / f, s.noise / f,
                s.NormalErrorMeanDeg(), s.normal_error_max_deg, s.F1(), s.PixelAccuracy());
  }
  if (!results.rep_rows.empty()) {
    std::printf("\n%-18s %-10s %8s %12s %12s %9s %7s %7s\n", "dataset", "method", "ms/frame",
                "med ang deg", "med off cm", "matching", "pairs", "large");
    for (const RepRow& r : results.rep_rows) {
      const auto& s = r.summary;
      std::printf("%-18s %-10s %8.2f %12.3f %12.3f %8.1f%% %7zu %7d\n", r.dataset.c_str(),
                  r.method.c_str(), Median(r.times_ms), s.MedianAngleDeg(),
                  100.0 * s.MedianOffset(), 100.0 * s.MatchingFraction(), s.angles_deg.size(),
                  s.large_planes);
    }
  }
  std::printf(
      "\ncorrect = correctly detected share of large GT planes; over/under/miss/noise = Hoover "
      "instances per frame\n(over, miss: large GT planes; under, noise: detected regions); ang = "
      "normal error of correct detections [deg];\nF1 at IoU >= 0.75; pixacc = share of large-GT "
      "pixels labelled with a region assigned to their plane;\nrepeatability: medians over matched "
      "large-plane pairs of the angle and offset after mapping frame i+k into frame i\nwith the "
      "ground-truth pose; matching = share of large planes of frame i with a partner.\n");
}

nlohmann::json SegmentationJson(const SegRow& r) {
  const auto& s = r.summary;
  return {{"dataset", r.dataset},
          {"method", r.method},
          {"kind", "segmentation"},
          {"frames", s.frames},
          {"median_ms", Median(r.times_ms)},
          {"gt_planes", s.gt_large},
          {"correct", s.correct_large},
          {"correct_rate", s.CorrectRate()},
          {"over_segmented", s.over_large},
          {"under_segmented", s.under_segmented},
          {"missed", s.missed_large},
          {"noise", s.noise},
          {"normal_error_mean_deg", s.NormalErrorMeanDeg()},
          {"normal_error_max_deg", s.normal_error_max_deg},
          {"precision", s.Precision()},
          {"recall", s.Recall()},
          {"f1", s.F1()},
          {"pixel_accuracy", s.PixelAccuracy()}};
}

nlohmann::json RepeatabilityJson(const RepRow& r) {
  const auto& s = r.summary;
  return {{"dataset", r.dataset},
          {"method", r.method},
          {"kind", "repeatability"},
          {"k", r.k},
          {"frame_pairs", s.frame_pairs},
          {"median_ms", Median(r.times_ms)},
          {"median_angle_deg", s.MedianAngleDeg()},
          {"median_offset_m", s.MedianOffset()},
          {"matched_pairs", s.angles_deg.size()},
          {"large_planes", s.large_planes},
          {"matching_fraction", s.MatchingFraction()}};
}

void WriteQualityJson(const std::string& path, const QualityResults& results) {
  nlohmann::json out = nlohmann::json::array();
  for (const SegRow& r : results.seg_rows) out.push_back(SegmentationJson(r));
  for (const RepRow& r : results.rep_rows) out.push_back(RepeatabilityJson(r));
  ds::WriteFileAtomic(path, out.dump(2) + "\n");
}

}  // namespace

void WriteTimePlots(const std::string& dir, const std::vector<std::string>& methods,
                    const std::vector<TimingSample>& samples) {
  EnsureDirectory(dir);
  // Times span two orders of magnitude (a few ms to hundreds), so both plots use a log10 axis.
  std::vector<BoxStats> boxes;
  SvgPlot scatter("Detection time vs planes found", "planes found", "log10(time per frame / ms)");
  int color = 0;
  for (const std::string& m : methods) {
    std::vector<double> logs, planes;
    for (const auto& s : samples) {
      if (s.method != m || !(s.ms > 0.0)) continue;
      logs.push_back(std::log10(s.ms));
      planes.push_back(s.planes);
    }
    if (logs.empty()) continue;
    boxes.push_back(ComputeBoxStats(m, logs));
    scatter.AddScatter(planes, logs, CycleColor(color++), m, 3.0);
  }
  SvgPlot box("Detection time per frame", "method", "log10(time per frame / ms)");
  box.AddBoxes(boxes);
  box.Write((fs::path(dir) / "detect_times.svg").string());
  scatter.Write((fs::path(dir) / "detect_time_vs_planes.svg").string());
}

int RunQualitySuite(const std::vector<Method>& methods, const Config& config,
                    const QualityOptions& options) {
  QualityResults results;
  const SyntheticCase cases[] = {{ds::SceneKind::kRoom, "pinhole"},
                                 {ds::SceneKind::kRoom, "spherical"},
                                 {ds::SceneKind::kRubble, "pinhole"},
                                 {ds::SceneKind::kRubble, "spherical"}};
  for (const SyntheticCase& c : cases) {
    if (!EvaluateSyntheticCase(c, methods, config, options, &results)) return kExitInterrupted;
  }
  const fs::path tum = fs::path(options.data_dir) / "tum_fr3_structure_notexture_far";
  if (fs::is_directory(tum)) {
    if (!EvaluateTumRepeatability(tum, methods, config, options, &results)) return kExitInterrupted;
  } else {
    std::cerr << "planeslam: note: " << tum.string()
              << " not found, TUM repeatability skipped (set PLANESLAM_DATA_DIR)\n";
  }

  PrintQualityTables(options, results);
  if (!options.json_path.empty()) WriteQualityJson(options.json_path, results);
  if (!options.plot_dir.empty()) {
    std::vector<std::string> names;
    for (const Method& m : methods) names.push_back(m.name);
    WriteTimePlots(options.plot_dir, names, results.samples);
  }
  return 0;
}

}  // namespace planeslam::app::bench

#include "kitti_report.hpp"

#include <cstdio>
#include <filesystem>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"

namespace planeslam::app {

namespace ds = planeslam::datasets;
namespace fs = std::filesystem;
namespace {
constexpr double kPi = 3.14159265358979323846;
}  // namespace

std::string FormatKittiErrors(const ds::KittiOdometryResult& r, std::size_t pairs) {
  std::string out;
  char line[160];
  std::snprintf(line, sizeof(line),
                "KITTI segment errors (devkit: first frame every 10, %zu segments, %zu poses, "
                "path %.1f m)\n",
                r.segments.size(), pairs, r.path_length);
  out += line;
  std::snprintf(line, sizeof(line), "translation  %.4f %%\nrotation     %.4f deg/100m\n",
                r.TranslationPercent(), r.RotationDegPer100m());
  out += line;
  out += "length [m]  segments  translation [%]  rotation [deg/100m]\n";
  for (const ds::KittiLengthErrors& l : r.per_length) {
    std::snprintf(line, sizeof(line), "%10.0f  %8zu  %15.4f  %19.4f\n", l.length, l.segments,
                  100.0 * l.t_err, l.r_err * 180.0 / kPi * 100.0);
    out += line;
  }
  return out;
}

nlohmann::json KittiErrorsJson(const ds::KittiOdometryResult& r) {
  nlohmann::json per_length = nlohmann::json::array();
  for (const ds::KittiLengthErrors& l : r.per_length) {
    per_length.push_back({{"length_m", l.length},
                          {"segments", l.segments},
                          {"translation_percent", 100.0 * l.t_err},
                          {"rotation_deg_per_100m", l.r_err * 180.0 / kPi * 100.0}});
  }
  return {{"translation_percent", r.TranslationPercent()},
          {"rotation_deg_per_100m", r.RotationDegPer100m()},
          {"segments", r.segments.size()},
          {"path_length_m", r.path_length},
          {"per_length", per_length}};
}

bool HasKittiGroundTruth(const std::string& sequence_path) {
  std::error_code ec;
  if (sequence_path.empty() || !fs::is_directory(sequence_path, ec)) return false;
  try {
    if (ds::DetectLayout(sequence_path) != ds::SequenceLayout::kKittiBin) return false;
  } catch (const IoError&) {
    return false;
  }
  fs::path dir = fs::path(sequence_path).lexically_normal();
  if (dir.filename().empty()) dir = dir.parent_path();
  if (dir.filename() == "velodyne") dir = dir.parent_path();
  return fs::is_regular_file(dir / "poses.txt", ec) ||
         fs::is_regular_file(dir.parent_path().parent_path() / "poses" /
                                 (dir.filename().string() + ".txt"),
                             ec);
}

std::optional<ds::KittiOdometryResult> KittiErrors(const ds::Trajectory& ground_truth,
                                                   const ds::Trajectory& estimate) {
  if (ground_truth.size() < 2 || estimate.size() < 2) return std::nullopt;
  const std::vector<ds::IndexPair> pairs =
      ds::AssociateNearest(ground_truth.stamps, estimate.stamps, 1e-6);
  if (pairs.size() < 2) return std::nullopt;
  std::vector<Pose> gt, est;
  for (const auto& [i, j] : pairs) {
    gt.push_back(ground_truth.poses[i]);
    est.push_back(estimate.poses[j]);
  }
  return ds::EvaluateKittiOdometry(gt, est);
}

void AddKittiErrors(const std::string& sequence_path, const ds::Trajectory& ground_truth,
                    const ds::Trajectory& estimate, nlohmann::json* metrics, std::string* report) {
  if (!HasKittiGroundTruth(sequence_path)) return;
  const auto kitti = KittiErrors(ground_truth, estimate);
  if (!kitti) return;
  if (!kitti->ok) {
    (*metrics)["kitti"] = {{"error", kitti->message}};
    *report += "\nKITTI segment errors: " + kitti->message;
    return;
  }
  (*metrics)["kitti"] = KittiErrorsJson(*kitti);
  char line[160];
  std::snprintf(line, sizeof(line),
                "\nKITTI segment errors: translation %.4f %%, rotation %.4f deg/100m (%zu "
                "segments, path %.1f m)",
                kitti->TranslationPercent(), kitti->RotationDegPer100m(), kitti->segments.size(),
                kitti->path_length);
  *report += line;
}

}  // namespace planeslam::app

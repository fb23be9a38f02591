#include "planeslam/datasets/segmentation_metrics.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

double LineAngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  // atan2(|a x b|, |a.b|) is accurate for small angles, where acos loses digits.
  const double c = std::abs(a.normalized().dot(b.normalized()));
  const double s = a.normalized().cross(b.normalized()).norm();
  return std::atan2(s, c) * 180.0 / M_PI;
}

}  // namespace

SegmentationMetrics EvaluateSegmentation(const std::vector<std::int32_t>& ground_truth,
                                         const std::vector<std::int32_t>& detected,
                                         const std::vector<Eigen::Vector3d>& gt_normals,
                                         const std::vector<Eigen::Vector3d>& detected_normals,
                                         const SegmentationMetricsOptions& options) {
  PLANESLAM_CHECK(ground_truth.size() == detected.size(),
                  "label images differ in size: " << ground_truth.size() << " vs "
                                                  << detected.size());
  PLANESLAM_CHECK(options.tolerance > 0.5 && options.tolerance <= 1.0,
                  "Hoover tolerance must be in (0.5, 1], got " << options.tolerance);
  PLANESLAM_CHECK(options.iou_threshold > 0.5 && options.iou_threshold <= 1.0,
                  "IoU threshold must be in (0.5, 1], got " << options.iou_threshold);
  const double T = options.tolerance;

  // Region sizes and the sparse overlap table O_mn.
  std::map<int, std::int64_t> gt_size, det_size;
  std::map<std::pair<int, int>, std::int64_t> overlap;
  for (std::size_t i = 0; i < ground_truth.size(); ++i) {
    const int m = ground_truth[i];
    const int n = detected[i];
    if (m > 0) ++gt_size[m];
    if (n > 0) ++det_size[n];
    if (m > 0 && n > 0) ++overlap[{m, n}];
  }

  SegmentationMetrics out;
  std::map<int, std::size_t> gt_index, det_index;
  for (const auto& [label, pixels] : gt_size) {
    gt_index[label] = out.gt_regions.size();
    out.gt_regions.push_back({label, pixels, RegionOutcome::kMissed, 0, -1.0});
  }
  for (const auto& [label, pixels] : det_size) {
    det_index[label] = out.detected_regions.size();
    out.detected_regions.push_back({label, pixels, RegionOutcome::kNoise});
  }
  auto& G = out.gt_regions;
  auto& D = out.detected_regions;
  std::vector<bool> gt_done(G.size(), false), det_done(D.size(), false);

  // 1. Correct detections (take precedence over everything else).
  for (const auto& [key, o] : overlap) {
    const std::size_t gi = gt_index[key.first], di = det_index[key.second];
    if (o >= T * G[gi].pixels && o >= T * D[di].pixels) {
      // Unique for T > 0.5 (labels are one per pixel), so no region is claimed twice.
      G[gi].outcome = RegionOutcome::kCorrect;
      G[gi].matched_label = key.second;
      D[di].outcome = RegionOutcome::kCorrect;
      gt_done[gi] = det_done[di] = true;
      ++out.correct;
    }
  }

  // 2. Over-segmentation: per remaining GT region, the detected regions mostly inside it.
  //    (Each detected region has at most one such GT region when T > 0.5.)
  std::map<std::size_t, std::vector<std::pair<std::size_t, std::int64_t>>> inside_gt;
  std::map<std::size_t, std::vector<std::pair<std::size_t, std::int64_t>>> inside_det;
  for (const auto& [key, o] : overlap) {
    const std::size_t gi = gt_index[key.first], di = det_index[key.second];
    if (gt_done[gi] || det_done[di]) continue;
    if (o >= T * D[di].pixels) inside_gt[gi].push_back({di, o});
    if (o >= T * G[gi].pixels) inside_det[di].push_back({gi, o});
  }
  for (const auto& [gi, parts] : inside_gt) {
    if (parts.size() < 2) continue;
    std::int64_t sum = 0;
    for (const auto& part : parts) sum += part.second;
    if (sum < T * G[gi].pixels) continue;
    G[gi].outcome = RegionOutcome::kOverSegmented;
    gt_done[gi] = true;
    for (const auto& part : parts) {
      D[part.first].outcome = RegionOutcome::kOverSegmented;
      det_done[part.first] = true;
    }
    ++out.over_segmented;
  }
  // 3. Under-segmentation: per remaining detected region, the GT regions mostly inside it. Cannot
  //    conflict with step 2 for T > 0.5 (a GT region mostly covered by one detected region cannot
  //    also be mostly covered by other, disjoint detected regions), the done flags just make sure.
  for (const auto& [di, parts] : inside_det) {
    if (parts.size() < 2 || det_done[di]) continue;
    std::int64_t sum = 0;
    bool free = true;
    for (const auto& part : parts) {
      sum += part.second;
      free = free && !gt_done[part.first];
    }
    if (!free || sum < T * D[di].pixels) continue;
    D[di].outcome = RegionOutcome::kUnderSegmented;
    det_done[di] = true;
    for (const auto& part : parts) {
      G[part.first].outcome = RegionOutcome::kUnderSegmented;
      gt_done[part.first] = true;
    }
    ++out.under_segmented;
  }
  // 4. The rest is missed / noise (the default outcomes).
  for (std::size_t gi = 0; gi < G.size(); ++gi) out.missed += gt_done[gi] ? 0 : 1;
  for (std::size_t di = 0; di < D.size(); ++di) out.noise += det_done[di] ? 0 : 1;

  // Rates over large GT regions, and normal errors of their correct pairs.
  double error_sum = 0.0;
  for (auto& g : G) {
    if (g.outcome == RegionOutcome::kCorrect) {
      const std::size_t gn = static_cast<std::size_t>(g.label - 1);
      const std::size_t dn = static_cast<std::size_t>(g.matched_label - 1);
      if (gn < gt_normals.size() && dn < detected_normals.size()) {
        g.normal_error_deg = LineAngleDeg(gt_normals[gn], detected_normals[dn]);
      }
    }
    if (g.pixels < options.min_gt_pixels) continue;
    ++out.gt_large;
    switch (g.outcome) {
      case RegionOutcome::kCorrect:
        ++out.correct_large;
        if (g.normal_error_deg >= 0.0) {
          error_sum += g.normal_error_deg;
          out.normal_error_max_deg = std::max(out.normal_error_max_deg, g.normal_error_deg);
          ++out.normal_error_count;
        }
        break;
      case RegionOutcome::kOverSegmented: ++out.over_large; break;
      case RegionOutcome::kUnderSegmented: ++out.under_large; break;
      default: ++out.missed_large; break;
    }
  }
  out.correct_rate = out.gt_large ? double(out.correct_large) / out.gt_large : 0.0;
  if (out.normal_error_count > 0) out.normal_error_mean_deg = error_sum / out.normal_error_count;

  // IoU matching: IoU > 0.5 makes the match unique on both sides.
  for (const auto& [key, o] : overlap) {
    const auto& g = G[gt_index[key.first]];
    const auto& d = D[det_index[key.second]];
    const double iou = double(o) / double(g.pixels + d.pixels - o);
    if (iou < options.iou_threshold) continue;
    ++out.iou_true_positives;
    if (g.pixels >= options.min_gt_pixels) ++out.iou_matched_large;
  }
  out.precision = D.empty() ? 0.0 : double(out.iou_true_positives) / D.size();
  out.recall = out.gt_large ? double(out.iou_matched_large) / out.gt_large : 0.0;
  out.f1 = out.precision + out.recall > 0.0
               ? 2.0 * out.precision * out.recall / (out.precision + out.recall)
               : 0.0;

  // Pixel accuracy: each detected region belongs to the GT region it overlaps most.
  std::map<int, std::pair<std::int64_t, int>> owner;  // detected label -> (overlap, gt label)
  for (const auto& [key, o] : overlap) {
    auto it = owner.find(key.second);
    // The map iterates GT labels in increasing order, so ">" keeps the lowest label on ties.
    if (it == owner.end() || o > it->second.first) owner[key.second] = {o, key.first};
  }
  for (const auto& g : G) {
    if (g.pixels >= options.min_gt_pixels) out.gt_large_pixels += g.pixels;
  }
  for (const auto& [key, o] : overlap) {
    if (gt_size[key.first] < options.min_gt_pixels) continue;
    if (owner[key.second].second == key.first) out.correct_pixels += o;
  }
  out.pixel_accuracy =
      out.gt_large_pixels ? double(out.correct_pixels) / out.gt_large_pixels : 0.0;
  return out;
}

void SegmentationSummary::Add(const SegmentationMetrics& m) {
  ++frames;
  gt_large += m.gt_large;
  correct_large += m.correct_large;
  over_large += m.over_large;
  under_segmented += m.under_segmented;
  missed_large += m.missed_large;
  noise += m.noise;
  detected += static_cast<int>(m.detected_regions.size());
  iou_true_positives += m.iou_true_positives;
  iou_matched_large += m.iou_matched_large;
  if (m.normal_error_count > 0) {
    normal_error_sum_deg += m.normal_error_mean_deg * m.normal_error_count;
    normal_error_max_deg = std::max(normal_error_max_deg, m.normal_error_max_deg);
    normal_error_count += m.normal_error_count;
  }
  gt_large_pixels += m.gt_large_pixels;
  correct_pixels += m.correct_pixels;
}

}  // namespace planeslam::datasets

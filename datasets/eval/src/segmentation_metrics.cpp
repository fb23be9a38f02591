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

/// Region sizes and the sparse overlap table O_mn of two label images.
struct Overlaps {
  std::map<int, std::int64_t> gt_size, det_size;
  std::map<std::pair<int, int>, std::int64_t> overlap;  ///< (gt label, detected label) -> pixels
};

Overlaps CountOverlaps(const std::vector<std::int32_t>& ground_truth,
                       const std::vector<std::int32_t>& detected) {
  Overlaps t;
  for (std::size_t i = 0; i < ground_truth.size(); ++i) {
    const int m = ground_truth[i];
    const int n = detected[i];
    if (m > 0) ++t.gt_size[m];
    if (n > 0) ++t.det_size[n];
    if (m > 0 && n > 0) ++t.overlap[{m, n}];
  }
  return t;
}

/// The SegComp classification in progress: the regions of both sides (indexed by their rank in
/// label order) and which of them are already classified.
class Classifier {
 public:
  Classifier(const Overlaps& t, double tolerance, SegmentationMetrics* out)
      : t_(t), T_(tolerance), out_(*out), G_(out->gt_regions), D_(out->detected_regions) {
    for (const auto& [label, pixels] : t.gt_size) {
      gt_index_[label] = G_.size();
      G_.push_back({label, pixels, RegionOutcome::kMissed, 0, -1.0});
    }
    for (const auto& [label, pixels] : t.det_size) {
      det_index_[label] = D_.size();
      D_.push_back({label, pixels, RegionOutcome::kNoise});
    }
    gt_done_.assign(G_.size(), false);
    det_done_.assign(D_.size(), false);
  }

  std::size_t GtIndex(int label) const { return gt_index_.at(label); }
  std::size_t DetIndex(int label) const { return det_index_.at(label); }

  /// 1. Correct detections (take precedence over everything else).
  void Correct() {
    for (const auto& [key, o] : t_.overlap) {
      const std::size_t gi = GtIndex(key.first), di = DetIndex(key.second);
      if (o >= T_ * G_[gi].pixels && o >= T_ * D_[di].pixels) {
        // Unique for T > 0.5 (labels are one per pixel), so no region is claimed twice.
        G_[gi].outcome = RegionOutcome::kCorrect;
        G_[gi].matched_label = key.second;
        D_[di].outcome = RegionOutcome::kCorrect;
        gt_done_[gi] = det_done_[di] = true;
        ++out_.correct;
      }
    }
  }

  /// 2. Over-segmentation, then 3. under-segmentation, over the regions not yet classified.
  void OverAndUnder() {
    // Per remaining GT region, the detected regions mostly inside it, and per remaining detected
    // region, the GT regions mostly inside it. (Each detected region has at most one such GT
    // region when T > 0.5, and conversely.)
    Parts inside_gt, inside_det;
    for (const auto& [key, o] : t_.overlap) {
      const std::size_t gi = GtIndex(key.first), di = DetIndex(key.second);
      if (gt_done_[gi] || det_done_[di]) continue;
      if (o >= T_ * D_[di].pixels) inside_gt[gi].push_back({di, o});
      if (o >= T_ * G_[gi].pixels) inside_det[di].push_back({gi, o});
    }
    OverSegmentation(inside_gt);
    UnderSegmentation(inside_det);
  }

  /// 4. The rest is missed / noise (the default outcomes).
  void CountRest() {
    for (std::size_t gi = 0; gi < G_.size(); ++gi) out_.missed += gt_done_[gi] ? 0 : 1;
    for (std::size_t di = 0; di < D_.size(); ++di) out_.noise += det_done_[di] ? 0 : 1;
  }

 private:
  /// Region index -> (index of a region on the other side, overlap) of the regions inside it.
  using Parts = std::map<std::size_t, std::vector<std::pair<std::size_t, std::int64_t>>>;

  void OverSegmentation(const Parts& inside_gt) {
    for (const auto& [gi, parts] : inside_gt) {
      if (parts.size() < 2) continue;
      std::int64_t sum = 0;
      for (const auto& part : parts) sum += part.second;
      if (sum < T_ * G_[gi].pixels) continue;
      G_[gi].outcome = RegionOutcome::kOverSegmented;
      gt_done_[gi] = true;
      for (const auto& part : parts) {
        D_[part.first].outcome = RegionOutcome::kOverSegmented;
        det_done_[part.first] = true;
      }
      ++out_.over_segmented;
    }
  }

  /// Cannot conflict with over-segmentation for T > 0.5 (a GT region mostly covered by one
  /// detected region cannot also be mostly covered by other, disjoint detected regions); the done
  /// flags just make sure.
  void UnderSegmentation(const Parts& inside_det) {
    for (const auto& [di, parts] : inside_det) {
      if (parts.size() < 2 || det_done_[di]) continue;
      std::int64_t sum = 0;
      bool free = true;
      for (const auto& part : parts) {
        sum += part.second;
        free = free && !gt_done_[part.first];
      }
      if (!free || sum < T_ * D_[di].pixels) continue;
      D_[di].outcome = RegionOutcome::kUnderSegmented;
      det_done_[di] = true;
      for (const auto& part : parts) {
        G_[part.first].outcome = RegionOutcome::kUnderSegmented;
        gt_done_[part.first] = true;
      }
      ++out_.under_segmented;
    }
  }

  const Overlaps& t_;
  const double T_;
  SegmentationMetrics& out_;
  std::vector<SegmentationMetrics::GtRegion>& G_;
  std::vector<SegmentationMetrics::DetectedRegion>& D_;
  std::map<int, std::size_t> gt_index_, det_index_;
  std::vector<bool> gt_done_, det_done_;
};

/// Rates over large GT regions, and normal errors of their correct pairs.
void LargeRegionRates(const std::vector<Eigen::Vector3d>& gt_normals,
                      const std::vector<Eigen::Vector3d>& detected_normals,
                      const SegmentationMetricsOptions& options, SegmentationMetrics* out) {
  double error_sum = 0.0;
  for (auto& g : out->gt_regions) {
    if (g.outcome == RegionOutcome::kCorrect) {
      const std::size_t gn = static_cast<std::size_t>(g.label - 1);
      const std::size_t dn = static_cast<std::size_t>(g.matched_label - 1);
      if (gn < gt_normals.size() && dn < detected_normals.size()) {
        g.normal_error_deg = LineAngleDeg(gt_normals[gn], detected_normals[dn]);
      }
    }
    if (g.pixels < options.min_gt_pixels) continue;
    ++out->gt_large;
    switch (g.outcome) {
      case RegionOutcome::kCorrect:
        ++out->correct_large;
        if (g.normal_error_deg >= 0.0) {
          error_sum += g.normal_error_deg;
          out->normal_error_max_deg = std::max(out->normal_error_max_deg, g.normal_error_deg);
          ++out->normal_error_count;
        }
        break;
      case RegionOutcome::kOverSegmented: ++out->over_large; break;
      case RegionOutcome::kUnderSegmented: ++out->under_large; break;
      default: ++out->missed_large; break;
    }
  }
  out->correct_rate = out->gt_large ? double(out->correct_large) / out->gt_large : 0.0;
  if (out->normal_error_count > 0) {
    out->normal_error_mean_deg = error_sum / out->normal_error_count;
  }
}

/// IoU matching (IoU > 0.5 makes the match unique on both sides): precision, recall, F1.
void IouMatching(const Overlaps& t, const Classifier& c, const SegmentationMetricsOptions& options,
                 SegmentationMetrics* out) {
  const auto& G = out->gt_regions;
  const auto& D = out->detected_regions;
  for (const auto& [key, o] : t.overlap) {
    const auto& g = G[c.GtIndex(key.first)];
    const auto& d = D[c.DetIndex(key.second)];
    const double iou = double(o) / double(g.pixels + d.pixels - o);
    if (iou < options.iou_threshold) continue;
    ++out->iou_true_positives;
    if (g.pixels >= options.min_gt_pixels) ++out->iou_matched_large;
  }
  out->precision = D.empty() ? 0.0 : double(out->iou_true_positives) / D.size();
  out->recall = out->gt_large ? double(out->iou_matched_large) / out->gt_large : 0.0;
  out->f1 = out->precision + out->recall > 0.0
                ? 2.0 * out->precision * out->recall / (out->precision + out->recall)
                : 0.0;
}

/// Pixel accuracy: each detected region belongs to the GT region it overlaps most.
void PixelAccuracy(const Overlaps& t, const SegmentationMetricsOptions& options,
                   SegmentationMetrics* out) {
  std::map<int, std::pair<std::int64_t, int>> owner;  // detected label -> (overlap, gt label)
  for (const auto& [key, o] : t.overlap) {
    auto it = owner.find(key.second);
    // The map iterates GT labels in increasing order, so ">" keeps the lowest label on ties.
    if (it == owner.end() || o > it->second.first) owner[key.second] = {o, key.first};
  }
  for (const auto& g : out->gt_regions) {
    if (g.pixels >= options.min_gt_pixels) out->gt_large_pixels += g.pixels;
  }
  for (const auto& [key, o] : t.overlap) {
    if (t.gt_size.at(key.first) < options.min_gt_pixels) continue;
    if (owner[key.second].second == key.first) out->correct_pixels += o;
  }
  out->pixel_accuracy =
      out->gt_large_pixels ? double(out->correct_pixels) / out->gt_large_pixels : 0.0;
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
  const Overlaps t = CountOverlaps(ground_truth, detected);
  SegmentationMetrics out;
  Classifier classifier(t, options.tolerance, &out);
  classifier.Correct();
  classifier.OverAndUnder();
  classifier.CountRest();
  LargeRegionRates(gt_normals, detected_normals, options, &out);
  IouMatching(t, classifier, options, &out);
  PixelAccuracy(t, options, &out);
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

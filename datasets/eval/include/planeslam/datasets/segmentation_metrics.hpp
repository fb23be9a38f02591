#pragma once
/// Quality of a plane segmentation against a ground-truth label image.
///
/// The region classification is Hoover et al., "An Experimental Comparison of Range Image
/// Segmentation Algorithms", PAMI 18(7), 1996 (SegComp). With M ground-truth regions R_m,
/// D detected regions R_n, O_mn = |R_m ∩ R_n| (pixels) and a tolerance 0.5 < T <= 1:
///  - correct detection (m, n):   O_mn >= T|R_m| and O_mn >= T|R_n|;
///  - over-segmentation of R_m:   detected R_n1..R_nx (x >= 2) with O_mni >= T|R_ni| for every i
///                                and sum_i O_mni >= T|R_m|;
///  - under-segmentation into R_n: ground-truth R_m1..R_mx (x >= 2) with O_min >= T|R_mi| for every
///                                i and sum_i O_min >= T|R_n|;
///  - missed: a ground-truth region in none of the above; noise: a detected region in none.
///
/// Overlapping cases. Because labels are one per pixel and T > 0.5, a region can be in at most one
/// correct pair, and over- and under-segmentation exclude each other. The one remaining overlap is
/// a correct pair (m, n) plus small detected regions lying inside R_m (which together with n also
/// satisfy the over-segmentation rule), and its mirror for under-segmentation. Correct detection
/// takes precedence: regions in a correct pair are removed before over/under-segmentation is
/// tested, so such small extra regions are counted as noise (or the extra ground-truth regions as
/// missed). The candidate set of an over-segmentation is every non-correct detected region with
/// O_mn >= T|R_n| (the largest set, hence the largest sum); likewise for under-segmentation.
///
/// Label conventions: ground truth 0 (or negative) = no plane, m >= 1 = region; detected -1 or 0 =
/// no plane, n >= 1 = region. Labels need not be consecutive. Region sizes count all pixels that
/// carry the label (so callers should label only pixels with a measurement).
#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace planeslam::datasets {

/// What happened to one region in the SegComp classification.
enum class RegionOutcome : std::uint8_t {
  kCorrect = 0,
  kOverSegmented = 1,   ///< a ground-truth region split into several detected ones
  kUnderSegmented = 2,  ///< several ground-truth regions merged into one detected region (either side)
  kMissed = 3,          ///< ground-truth only
  kNoise = 4,           ///< detected only
};

/// Options of EvaluateSegmentation.
struct SegmentationMetricsOptions {
  double tolerance = 0.8;        ///< Hoover's T, must be in (0.5, 1]
  double iou_threshold = 0.75;   ///< region match for precision/recall/F1, must be > 0.5
  /// Ground-truth regions smaller than this [px] are still classified, but left out of the rates
  /// (correct_rate, recall, normal errors, pixel accuracy), which are "of the GT planes >= N px".
  std::int64_t min_gt_pixels = 0;
};

/// Per-region detail and the aggregate figures of one frame.
struct SegmentationMetrics {
  struct GtRegion {
    int label = 0;
    std::int64_t pixels = 0;
    RegionOutcome outcome = RegionOutcome::kMissed;
    int matched_label = 0;         ///< the detected label of a correct pair, else 0
    double normal_error_deg = -1;  ///< for correct pairs with both normals known, else -1
  };
  struct DetectedRegion {
    int label = 0;
    std::int64_t pixels = 0;
    RegionOutcome outcome = RegionOutcome::kNoise;
  };
  std::vector<GtRegion> gt_regions;            ///< sorted by label
  std::vector<DetectedRegion> detected_regions;  ///< sorted by label

  // SegComp counts (instances, over all regions regardless of size).
  int correct = 0;             ///< correct pairs
  int over_segmented = 0;      ///< ground-truth regions over-segmented
  int under_segmented = 0;     ///< detected regions that under-segment
  int missed = 0;              ///< ground-truth regions
  int noise = 0;               ///< detected regions

  // Rates over the ground-truth regions with at least min_gt_pixels pixels ("large").
  int gt_large = 0;            ///< number of large ground-truth regions
  int correct_large = 0;       ///< of them correctly detected
  int over_large = 0;          ///< of them over-segmented
  int under_large = 0;         ///< of them part of an under-segmentation
  int missed_large = 0;        ///< of them missed
  double correct_rate = 0.0;   ///< correct_large / gt_large (0 when gt_large == 0)

  // Region matching at IoU >= iou_threshold (unique for a threshold > 0.5).
  int iou_true_positives = 0;  ///< detected regions matching a ground-truth region (any size)
  int iou_matched_large = 0;   ///< large ground-truth regions matched by a detected region
  double precision = 0.0;      ///< iou_true_positives / detected regions (0 when none)
  double recall = 0.0;         ///< iou_matched_large / gt_large
  double f1 = 0.0;

  // Normal accuracy of the correctly detected large planes: angle between the lines (orientation
  // sign ignored, as it is a convention) [deg]; -1 when there is none.
  double normal_error_mean_deg = -1.0;
  double normal_error_max_deg = -1.0;
  int normal_error_count = 0;

  /// Fraction of pixels of large ground-truth regions whose detected label is a region assigned to
  /// that ground-truth region; each detected region is assigned to the ground-truth region it
  /// overlaps most (ties: lowest label).
  double pixel_accuracy = 0.0;
  std::int64_t gt_large_pixels = 0;  ///< denominator of pixel_accuracy
  std::int64_t correct_pixels = 0;   ///< numerator of pixel_accuracy
};

/// Classifies the regions of `detected` against `ground_truth` (same size, row-major).
/// `gt_normals[m - 1]` is the unit normal of ground-truth label m and `detected_normals[n - 1]`
/// that of detected label n, in the same frame; either may be empty or shorter (then the labels
/// beyond it have no normal and are left out of the normal error).
/// Throws CheckError when the sizes differ or the options are out of range.
SegmentationMetrics EvaluateSegmentation(const std::vector<std::int32_t>& ground_truth,
                                         const std::vector<std::int32_t>& detected,
                                         const std::vector<Eigen::Vector3d>& gt_normals,
                                         const std::vector<Eigen::Vector3d>& detected_normals,
                                         const SegmentationMetricsOptions& options = {});

/// Sums of SegmentationMetrics over frames (rates recomputed from the pooled counts, normal errors
/// pooled over all correct pairs of large regions). Over-segmentation and missed count large
/// ground-truth regions; under-segmentation and noise count detected regions (of any size).
struct SegmentationSummary {
  int frames = 0;
  int gt_large = 0;
  int correct_large = 0;
  int over_large = 0;
  int under_segmented = 0;
  int missed_large = 0;
  int noise = 0;
  int detected = 0;
  int iou_true_positives = 0;
  int iou_matched_large = 0;
  double normal_error_sum_deg = 0.0;
  double normal_error_max_deg = -1.0;
  int normal_error_count = 0;
  std::int64_t gt_large_pixels = 0;
  std::int64_t correct_pixels = 0;

  void Add(const SegmentationMetrics& m);
  double CorrectRate() const { return gt_large ? double(correct_large) / gt_large : 0.0; }
  double Precision() const {
    return detected ? double(iou_true_positives) / detected : 0.0;
  }
  double Recall() const { return gt_large ? double(iou_matched_large) / gt_large : 0.0; }
  double F1() const {
    const double p = Precision(), r = Recall();
    return p + r > 0.0 ? 2.0 * p * r / (p + r) : 0.0;
  }
  double NormalErrorMeanDeg() const {
    return normal_error_count ? normal_error_sum_deg / normal_error_count : -1.0;
  }
  double PixelAccuracy() const {
    return gt_large_pixels ? double(correct_pixels) / gt_large_pixels : 0.0;
  }
};

}  // namespace planeslam::datasets

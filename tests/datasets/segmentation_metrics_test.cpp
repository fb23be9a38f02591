// Hoover et al. (PAMI 1996) region classification on small hand-made label images whose outcome
// is known for every category.
#include "planeslam/datasets/segmentation_metrics.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

constexpr int kWidth = 10;

/// A kWidth x rows label image filled with `fill`.
std::vector<std::int32_t> Image(int rows, std::int32_t fill) {
  return std::vector<std::int32_t>(static_cast<std::size_t>(rows) * kWidth, fill);
}
void SetRow(std::vector<std::int32_t>& img, int row, std::int32_t label, int col0 = 0,
            int col1 = kWidth) {
  for (int c = col0; c < col1; ++c) img[static_cast<std::size_t>(row) * kWidth + c] = label;
}

/// The scene of the class comment, one region per category (10 x 10 px):
///  rows 0-1: GT 1 == detected 1            -> correct
///  rows 2-3: GT 2 split into detected 2, 3 -> over-segmentation
///  row 4 GT 3, row 5 GT 4, detected 4      -> under-segmentation
///  rows 6-7: GT 5, nothing detected        -> missed
///  row 8: no GT, detected 5                -> noise
struct AllCategories {
  std::vector<std::int32_t> gt = Image(10, 0);
  std::vector<std::int32_t> det = Image(10, -1);
  AllCategories() {
    SetRow(gt, 0, 1), SetRow(gt, 1, 1), SetRow(det, 0, 1), SetRow(det, 1, 1);
    SetRow(gt, 2, 2), SetRow(gt, 3, 2), SetRow(det, 2, 2), SetRow(det, 3, 3);
    SetRow(gt, 4, 3), SetRow(gt, 5, 4), SetRow(det, 4, 4), SetRow(det, 5, 4);
    SetRow(gt, 6, 5), SetRow(gt, 7, 5);
    SetRow(det, 8, 5);
  }
};

TEST(SegmentationMetrics, EveryCategoryCountedOnce) {
  const AllCategories s;
  const SegmentationMetrics m = EvaluateSegmentation(s.gt, s.det, {}, {});
  EXPECT_EQ(m.correct, 1);
  EXPECT_EQ(m.over_segmented, 1);
  EXPECT_EQ(m.under_segmented, 1);
  EXPECT_EQ(m.missed, 1);
  EXPECT_EQ(m.noise, 1);
  ASSERT_EQ(m.gt_regions.size(), 5u);
  ASSERT_EQ(m.detected_regions.size(), 5u);
  EXPECT_EQ(m.gt_regions[0].outcome, RegionOutcome::kCorrect);
  EXPECT_EQ(m.gt_regions[0].matched_label, 1);
  EXPECT_EQ(m.gt_regions[1].outcome, RegionOutcome::kOverSegmented);
  EXPECT_EQ(m.gt_regions[2].outcome, RegionOutcome::kUnderSegmented);
  EXPECT_EQ(m.gt_regions[3].outcome, RegionOutcome::kUnderSegmented);
  EXPECT_EQ(m.gt_regions[4].outcome, RegionOutcome::kMissed);
  EXPECT_EQ(m.detected_regions[1].outcome, RegionOutcome::kOverSegmented);
  EXPECT_EQ(m.detected_regions[2].outcome, RegionOutcome::kOverSegmented);
  EXPECT_EQ(m.detected_regions[3].outcome, RegionOutcome::kUnderSegmented);
  EXPECT_EQ(m.detected_regions[4].outcome, RegionOutcome::kNoise);
  // No size filter: all 5 GT regions count; one correct.
  EXPECT_EQ(m.gt_large, 5);
  EXPECT_DOUBLE_EQ(m.correct_rate, 0.2);
  // Pixels: GT1 20 ok, GT2 20 ok (both pieces belong to it), GT3 10 ok (detected 4 is assigned to
  // the lowest label on the 10/10 tie), GT4 0, GT5 0 -> 50 of 80.
  EXPECT_EQ(m.gt_large_pixels, 80);
  EXPECT_EQ(m.correct_pixels, 50);
  EXPECT_DOUBLE_EQ(m.pixel_accuracy, 50.0 / 80.0);
  // IoU: only (1,1) reaches 0.75 -> precision 1/5, recall 1/5.
  EXPECT_EQ(m.iou_true_positives, 1);
  EXPECT_DOUBLE_EQ(m.precision, 0.2);
  EXPECT_DOUBLE_EQ(m.recall, 0.2);
  EXPECT_DOUBLE_EQ(m.f1, 0.2);
}

TEST(SegmentationMetrics, SizeFilterOnlyChangesTheRates) {
  const AllCategories s;
  SegmentationMetricsOptions options;
  options.min_gt_pixels = 15;  // drops GT 3 and 4 (10 px each) from the rates
  const SegmentationMetrics m = EvaluateSegmentation(s.gt, s.det, {}, {}, options);
  EXPECT_EQ(m.under_segmented, 1);  // classification itself is unchanged
  EXPECT_EQ(m.gt_large, 3);
  EXPECT_EQ(m.correct_large, 1);
  EXPECT_EQ(m.over_large, 1);
  EXPECT_EQ(m.under_large, 0);
  EXPECT_EQ(m.missed_large, 1);
  EXPECT_DOUBLE_EQ(m.correct_rate, 1.0 / 3.0);
  EXPECT_EQ(m.gt_large_pixels, 60);
  EXPECT_EQ(m.correct_pixels, 40);
  EXPECT_DOUBLE_EQ(m.recall, 1.0 / 3.0);
}

TEST(SegmentationMetrics, ToleranceBoundaryIsInclusive) {
  // GT 1: row 0 (10 px). Detected 1: 8 px of row 0 + 2 px of row 1 -> O = 8 = 0.8 * 10 both ways.
  auto gt = Image(2, 0);
  auto det = Image(2, 0);
  SetRow(gt, 0, 1);
  SetRow(det, 0, 1, 0, 8);
  SetRow(det, 1, 1, 0, 2);
  SegmentationMetricsOptions options;
  options.tolerance = 0.8;
  EXPECT_EQ(EvaluateSegmentation(gt, det, {}, {}, options).correct, 1);
  options.tolerance = 0.85;
  const SegmentationMetrics strict = EvaluateSegmentation(gt, det, {}, {}, options);
  EXPECT_EQ(strict.correct, 0);
  EXPECT_EQ(strict.missed, 1);
  EXPECT_EQ(strict.noise, 1);
}

TEST(SegmentationMetrics, CorrectDetectionTakesPrecedenceOverOverSegmentation) {
  // GT 1: rows 0-2 (30 px). Detected 1: 26 px of it (>= 0.8 * 30 = 24), detected 2: the other 4 px.
  // {1, 2} would also satisfy over-segmentation; correct wins and detected 2 is noise.
  auto gt = Image(3, 0);
  auto det = Image(3, -1);
  for (int r = 0; r < 3; ++r) SetRow(gt, r, 1);
  SetRow(det, 0, 1), SetRow(det, 1, 1), SetRow(det, 2, 1, 0, 6);
  SetRow(det, 2, 2, 6, 10);
  const SegmentationMetrics m = EvaluateSegmentation(gt, det, {}, {});
  EXPECT_EQ(m.correct, 1);
  EXPECT_EQ(m.over_segmented, 0);
  EXPECT_EQ(m.noise, 1);
  EXPECT_EQ(m.detected_regions[1].outcome, RegionOutcome::kNoise);
}

TEST(SegmentationMetrics, CorrectDetectionTakesPrecedenceOverUnderSegmentation) {
  // Mirror image: detected 1 covers GT 1 (26 px) and GT 2 (4 px); GT 2 becomes missed.
  auto gt = Image(3, 0);
  auto det = Image(3, 0);
  for (int r = 0; r < 3; ++r) SetRow(det, r, 1);
  SetRow(gt, 0, 1), SetRow(gt, 1, 1), SetRow(gt, 2, 1, 0, 6);
  SetRow(gt, 2, 2, 6, 10);
  const SegmentationMetrics m = EvaluateSegmentation(gt, det, {}, {});
  EXPECT_EQ(m.correct, 1);
  EXPECT_EQ(m.under_segmented, 0);
  EXPECT_EQ(m.missed, 1);
  EXPECT_EQ(m.gt_regions[1].outcome, RegionOutcome::kMissed);
}

TEST(SegmentationMetrics, PiecesTooSmallToCoverAreMissedAndNoise) {
  // GT 1: rows 0-1 (20 px); two detected pieces of 7 px inside it: 14 < 0.8 * 20.
  auto gt = Image(2, 0);
  auto det = Image(2, 0);
  SetRow(gt, 0, 1), SetRow(gt, 1, 1);
  SetRow(det, 0, 1, 0, 7);
  SetRow(det, 1, 2, 0, 7);
  const SegmentationMetrics m = EvaluateSegmentation(gt, det, {}, {});
  EXPECT_EQ(m.over_segmented, 0);
  EXPECT_EQ(m.missed, 1);
  EXPECT_EQ(m.noise, 2);
  // Both pieces still belong to GT 1 for the pixel accuracy: 14 of 20.
  EXPECT_DOUBLE_EQ(m.pixel_accuracy, 0.7);
}

TEST(SegmentationMetrics, NormalErrorOfCorrectPairsIgnoresSign) {
  // Two correct pairs with non-consecutive labels; detected normals tilted by 1 and 3 degrees,
  // the second also flipped in sign.
  auto gt = Image(2, 0);
  auto det = Image(2, -1);
  SetRow(gt, 0, 1), SetRow(gt, 1, 3);
  SetRow(det, 0, 2), SetRow(det, 1, 1);
  const double a1 = 1.0 * M_PI / 180.0, a3 = 3.0 * M_PI / 180.0;
  const std::vector<Eigen::Vector3d> gt_normals = {Eigen::Vector3d::UnitZ(),
                                                   Eigen::Vector3d::UnitX(),
                                                   Eigen::Vector3d::UnitY()};
  const std::vector<Eigen::Vector3d> det_normals = {
      -Eigen::Vector3d(0.0, std::cos(a3), std::sin(a3)),  // label 1 <-> GT 3 (UnitY)
      Eigen::Vector3d(std::sin(a1), 0.0, std::cos(a1))};  // label 2 <-> GT 1 (UnitZ)
  const SegmentationMetrics m = EvaluateSegmentation(gt, det, gt_normals, det_normals);
  ASSERT_EQ(m.correct, 2);
  EXPECT_EQ(m.normal_error_count, 2);
  EXPECT_NEAR(m.gt_regions[0].normal_error_deg, 1.0, 1e-9);
  EXPECT_NEAR(m.gt_regions[1].normal_error_deg, 3.0, 1e-9);
  EXPECT_NEAR(m.normal_error_mean_deg, 2.0, 1e-9);
  EXPECT_NEAR(m.normal_error_max_deg, 3.0, 1e-9);
  // Without detected normals the error is unknown, not zero.
  const SegmentationMetrics none = EvaluateSegmentation(gt, det, gt_normals, {});
  EXPECT_EQ(none.normal_error_count, 0);
  EXPECT_DOUBLE_EQ(none.normal_error_mean_deg, -1.0);
}

TEST(SegmentationMetrics, IouThresholdDecidesPrecisionAndRecall) {
  // GT 1 == detected 1 (IoU 1); GT 2 = row 1, detected 2 = 7 px of it (IoU 0.7 < 0.75);
  // detected 3 on background.
  auto gt = Image(3, 0);
  auto det = Image(3, 0);
  SetRow(gt, 0, 1), SetRow(det, 0, 1);
  SetRow(gt, 1, 2), SetRow(det, 1, 2, 0, 7);
  SetRow(det, 2, 3);
  const SegmentationMetrics m = EvaluateSegmentation(gt, det, {}, {});
  EXPECT_EQ(m.iou_true_positives, 1);
  EXPECT_DOUBLE_EQ(m.precision, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(m.recall, 0.5);
  EXPECT_DOUBLE_EQ(m.f1, 2.0 * (1.0 / 3.0) * 0.5 / (1.0 / 3.0 + 0.5));
  SegmentationMetricsOptions loose;
  loose.iou_threshold = 0.6;
  EXPECT_EQ(EvaluateSegmentation(gt, det, {}, {}, loose).iou_true_positives, 2);
}

TEST(SegmentationMetrics, EmptyImagesGiveZerosNotNan) {
  const auto gt = Image(2, 0);
  const auto det = Image(2, -1);
  const SegmentationMetrics m = EvaluateSegmentation(gt, det, {}, {});
  EXPECT_EQ(m.correct + m.missed + m.noise, 0);
  EXPECT_EQ(m.correct_rate, 0.0);
  EXPECT_EQ(m.precision, 0.0);
  EXPECT_EQ(m.pixel_accuracy, 0.0);
}

TEST(SegmentationMetrics, SummaryPoolsCounts) {
  const AllCategories s;
  SegmentationSummary sum;
  sum.Add(EvaluateSegmentation(s.gt, s.gt, {}, {}));  // perfect: 5 of 5
  sum.Add(EvaluateSegmentation(s.gt, s.det, {}, {}));  // 1 of 5
  EXPECT_EQ(sum.frames, 2);
  EXPECT_EQ(sum.gt_large, 10);
  EXPECT_EQ(sum.correct_large, 6);
  EXPECT_DOUBLE_EQ(sum.CorrectRate(), 0.6);
  EXPECT_EQ(sum.missed_large, 1);
  EXPECT_EQ(sum.noise, 1);
  EXPECT_EQ(sum.detected, 10);
  EXPECT_DOUBLE_EQ(sum.Precision(), 0.6);
  EXPECT_DOUBLE_EQ(sum.PixelAccuracy(), (80.0 + 50.0) / 160.0);
}

TEST(SegmentationMetrics, RejectsBadInput) {
  EXPECT_THROW(EvaluateSegmentation(Image(2, 0), Image(3, 0), {}, {}), CheckError);
  SegmentationMetricsOptions bad;
  bad.tolerance = 0.5;  // Hoover's uniqueness arguments need T > 0.5
  EXPECT_THROW(EvaluateSegmentation(Image(2, 0), Image(2, 0), {}, {}, bad), CheckError);
}

}  // namespace
}  // namespace planeslam::datasets

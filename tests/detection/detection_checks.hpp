#pragma once
// Checks a Segmentation against the ray-cast ground truth of a SyntheticFrame.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <string>

#include "planeslam/detection/plane_detector.hpp"
#include "synthetic_scene.hpp"

namespace planeslam::test {

/// For every ground-truth plane with at least `min_pixels` pixels: the detected plane that covers
/// most of its pixels must exist, cover at least half of them, and match within the tolerances.
inline void ExpectPlanesFound(const SyntheticFrame& frame, const detection::Segmentation& seg,
                              int min_pixels, double max_angle_deg, double max_offset_m,
                              const std::string& what) {
  ASSERT_EQ(seg.labels.size(), frame.gt_labels.size());
  for (const auto& p : seg.planes) {
    EXPECT_NEAR(p.normal.norm(), 1.0, 1e-9);
    EXPECT_GE(p.d, 0.0);
  }
  for (std::size_t g = 0; g < frame.planes.size(); ++g) {
    int gt_pixels = 0;
    std::map<int, int> overlap;
    for (std::size_t i = 0; i < frame.gt_labels.size(); ++i) {
      if (frame.gt_labels[i] != static_cast<int>(g)) continue;
      ++gt_pixels;
      if (seg.labels[i] >= 1) ++overlap[seg.labels[i]];
    }
    if (gt_pixels < min_pixels) continue;
    int best = -1, best_count = 0;
    for (const auto& [id, count] : overlap) {
      if (count > best_count) {
        best = id;
        best_count = count;
      }
    }
    ASSERT_GE(best, 1) << what << ": ground-truth plane " << g << " (" << gt_pixels
                       << " px) not detected";
    EXPECT_GE(best_count, gt_pixels / 2) << what << ": plane " << g << " mostly missed";
    const auto& det = seg.planes[best - 1];
    ASSERT_EQ(det.id, best);
    const double angle =
        std::acos(std::min(1.0, std::abs(det.normal.dot(frame.planes[g].normal)))) * 180.0 / M_PI;
    EXPECT_LT(angle, max_angle_deg) << what << ": plane " << g << " normal error";
    EXPECT_GT(det.normal.dot(frame.planes[g].normal), 0.0) << what << ": orientation";
    EXPECT_LT(std::abs(det.d - frame.planes[g].d), max_offset_m)
        << what << ": plane " << g << " offset error";
  }
}

}  // namespace planeslam::test

#pragma once
// Checks a Segmentation against the ground truth of a rendered SyntheticFrame.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "planeslam/detection/plane_detector.hpp"
#include "synthetic_scene.hpp"

namespace planeslam::test {

/// A ground-truth plane not found, and how.
struct PlaneNotFound {
  int plane;         ///< index into SyntheticFrame::planes
  std::string what;  ///< e.g. "ground-truth plane 3 (5000 px) found 0.6 deg and 0.03 m off"
};

/// For every ground-truth plane with at least `min_pixels` pixels: the detected plane that covers
/// most of its pixels must exist, cover at least half of them, face the same way and match within
/// the tolerances. Returns the planes that do not (empty: all found).
inline std::vector<PlaneNotFound> PlanesNotFound(const SyntheticFrame& frame,
                                               const detection::Segmentation& seg, int min_pixels,
                                               double max_angle_deg, double max_offset_m) {
  std::vector<PlaneNotFound> failures;
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
    std::ostringstream what;
    what << "ground-truth plane " << g << " (" << gt_pixels << " px)";
    if (best < 1 || best > static_cast<int>(seg.planes.size())) {
      failures.push_back({static_cast<int>(g), what.str() + " not detected"});
      continue;
    }
    const auto& det = seg.planes[best - 1];
    const double cosine = det.normal.dot(frame.planes[g].normal);
    const double angle = std::acos(std::min(1.0, std::abs(cosine))) * 180.0 / M_PI;
    const double offset = std::abs(det.d - frame.planes[g].d);
    if (best_count < gt_pixels / 2) {
      what << " mostly missed (" << best_count << " px in plane " << best << ")";
    } else if (det.id != best || cosine <= 0.0) {
      what << " found as plane " << best << " with id " << det.id << ", facing " << cosine;
    } else if (!(angle < max_angle_deg) || !(offset < max_offset_m)) {
      what << " found " << angle << " deg and " << offset << " m off";
    } else {
      continue;
    }
    failures.push_back({static_cast<int>(g), what.str()});
  }
  return failures;
}

/// PlanesNotFound as test failures, and the detected planes' own invariants (unit normal, d >= 0).
inline void ExpectPlanesFound(const SyntheticFrame& frame, const detection::Segmentation& seg,
                              int min_pixels, double max_angle_deg, double max_offset_m,
                              const std::string& what) {
  ASSERT_EQ(seg.labels.size(), frame.gt_labels.size());
  for (const auto& p : seg.planes) {
    EXPECT_NEAR(p.normal.norm(), 1.0, 1e-9);
    EXPECT_GE(p.d, 0.0);
  }
  for (const PlaneNotFound& failure :
       PlanesNotFound(frame, seg, min_pixels, max_angle_deg, max_offset_m)) {
    ADD_FAILURE() << what << ": " << failure.what;
  }
}

}  // namespace planeslam::test

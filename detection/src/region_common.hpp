#pragma once
// Machinery shared by GBRG and PBRG after growth: merging adjacent coplanar regions and turning
// region sums + a region-index image into a Segmentation (planes sorted by size, ids 1..N).
#include <cstdint>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "fast_moments.hpp"
#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/plane.hpp"

namespace planeslam::detection::internal {

/// This thread's instance of a detector's scratch buffers of type T, kept across frames so that
/// a warmed-up detector allocates nothing per frame.
template <class T>
T& ThreadScratch() {
  thread_local T scratch;
  return scratch;
}

/// Depth used by the noise model: z for a pinhole camera, range for a spherical scanner.
inline float PointDepth(const Eigen::Vector3f& p, bool spherical) {
  return spherical ? p.norm() : p.z();
}

/// A pixel may change to a neighbouring region only when that region's plane passes within this
/// many sigma(s) of it along its ray (three sigma of the sensor noise: plausibly its surface).
constexpr double kCreaseGateSigmas = 3.0;

/// A region's plane from the ray fit, and its centroid (which side of another plane it lies on).
struct RayPlane {
  bool ok = false;  ///< false: no ray fit (too few pixels, or rays spanning a line)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double d = 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
};

/// The ray fit of a region with ray sums `sums` and moments `region` (not ok under 3 points).
RayPlane SolveRegion(const RaySums& sums, const MomentSums& region);

/// Whether the ray of point p (at depth or range s) meets `other`'s plane within
/// kCreaseGateSigmas sigma(s) of p (anywhere in front of the sensor when the model has no noise);
/// the depth where it meets it in `s_other`.
bool WithinCreaseGate(const Eigen::Vector3d& p, double s, const RayPlane& other,
                      const DetectionParams& params, double* s_other);

/// For a pixel within the crease gate of `other` (its ray meets that plane at `s_other`):
/// whether its ray sees `other`'s surface where the two planes meet (see VisibleHere).
bool SeesOther(const Eigen::Vector3d& p, double s, double s_other, const RayPlane& own,
               const RayPlane& other);

/// Whether pixel p of region `own` shows region `other`'s surface instead: `other`'s plane is
/// within kCreaseGateSigmas sigma(s) along the ray, and it is the plane the ray sees where the
/// two meet. At a concave crease (each region in front of the other's plane, e.g. a wall corner
/// or a box on the floor) the ray sees the nearer of the two planes; at a convex one (each behind
/// the other's plane, a box's edge) the farther. Where the regions are neither (planes crossing),
/// the nearer along the ray to the measured point wins. The planes come from all the regions'
/// pixels, so where their crease runs is known far better than from any one pixel's depth.
bool VisibleHere(const Eigen::Vector3f& p, double s, const RayPlane& own, const RayPlane& other,
                 const DetectionParams& params);

/// Which of two planes the valid pixels of the 3x3 window around pixel (x, y) lie on: their
/// mean point is within kCreaseGateSigmas of its noise (sigma / sqrt(n)) from one plane only,
/// along its ray; undecided where it fits both (near the line where they meet), neither (a
/// window across a depth edge), or under five pixels are valid.
enum class CreaseEvidence { kOwn, kOther, kUndecided };
CreaseEvidence NeighbourhoodEvidence(const datasets::OrganizedCloud& cloud, int x, int y,
                                     bool spherical, const RayPlane& own, const RayPlane& other,
                                     const DetectionParams& params);

/// How far along its ray (at depth or range s) point p lies from the plane: |s_plane - s|, or
/// infinity when the ray does not meet the plane in front of the sensor.
double RayOffset(const Eigen::Vector3f& p, double s, const RayPlane& plane);

/// Where regions meet in a region-index image (-1 = none).
struct RegionBorders {
  std::vector<std::size_t> pixels;   ///< pixels 4-adjacent to a pixel of another region, once each
  std::vector<std::uint64_t> pairs;  ///< regions that touch, lo << 32 | hi, sorted and unique
};

/// Collects RegionBorders, pixel pair by pixel pair or from parts of the image (GBRG scans only
/// the grids on a region's edge: its interior grids hold one label and so hold no border).
class RegionBorderScan {
 public:
  RegionBorderScan(const std::vector<std::int32_t>& labels, int width, int height);
  /// Records pixel i of region r and its 4-neighbour j, which lies in another region (>= 0).
  void Add(std::size_t i, std::int32_t r, std::size_t j);
  /// Looks at every pixel of [x0, x1) x [y0, y1) and its four neighbours (also outside it).
  /// Inline, with bounds checks only for a block that touches the image border: GBRG scans each
  /// edge grid (k x k pixels) with a call of its own.
  void Scan(int x0, int y0, int x1, int y1) {
    if (x0 > 0 && y0 > 0 && x1 < width_ && y1 < height_) {
      ScanBlock<false>(x0, y0, x1, y1);
    } else {
      ScanBlock<true>(x0, y0, x1, y1);
    }
  }
  /// The borders found, pairs sorted and unique.
  RegionBorders Finish();

 private:
  template <bool kAtImageBorder>
  void ScanBlock(int x0, int y0, int x1, int y1) {
#if defined(__SSE2__)
    if constexpr (!kAtImageBorder) {
      if (x1 - x0 <= 4 && x0 + 4 < width_) {
        ScanNarrowBlock(x0, y0, x1, y1);
        return;
      }
    }
#endif
    for (int y = y0; y < y1; ++y) {
      for (int x = x0; x < x1; ++x) ScanPixel<kAtImageBorder>(x, y);
    }
  }

  template <bool kAtImageBorder>
  void ScanPixel(int x, int y) {
    const auto w = static_cast<std::size_t>(width_);
    const std::int32_t* labels = labels_.data();
    const std::size_t i = static_cast<std::size_t>(y) * w + x;
    const std::int32_t r = labels[i];
    if (r < 0) return;
    const std::int32_t left = !kAtImageBorder || x > 0 ? labels[i - 1] : r;
    const std::int32_t right = !kAtImageBorder || x + 1 < width_ ? labels[i + 1] : r;
    const std::int32_t up = !kAtImageBorder || y > 0 ? labels[i - w] : r;
    const std::int32_t down = !kAtImageBorder || y + 1 < height_ ? labels[i + w] : r;
    auto other = [r](std::int32_t o) { return (o >= 0) & (o != r); };
    // Most pixels, even in the grids scanned, have no other region around: one branch for the
    // four neighbours, taken the same way along a region's interior.
    if (!(other(left) | other(right) | other(up) | other(down))) return;
    if (other(left)) Add(i, r, i - 1);
    if (other(right)) Add(i, r, i + 1);
    if (other(up)) Add(i, r, i - w);
    if (other(down)) Add(i, r, i + w);
  }

#if defined(__SSE2__)
  /// A block at most four pixels wide inside the image (GBRG's 3x3 and 4x4 edge grids): each row
  /// first asks, four pixels at once, whether any of its pixels has another region around; only
  /// such rows are scanned pixel by pixel (where most rows have none, a branch per pixel missed).
  /// Its loads take four labels from columns x0 - 1, x0 and x0 + 1 of a row and x0 in the rows
  /// above and below, whatever the block's width: inside the image for x0 > 0, x0 + 4 < width
  /// and rows 1 to height - 2 (the caller's conditions).
  void ScanNarrowBlock(int x0, int y0, int x1, int y1) {
    const auto w = static_cast<std::size_t>(width_);
    const __m128i in_block = _mm_cmpgt_epi32(_mm_set1_epi32(x1 - x0), _mm_setr_epi32(0, 1, 2, 3));
    const __m128i none = _mm_set1_epi32(-1);
    for (int y = y0; y < y1; ++y) {
      const std::int32_t* row = labels_.data() + static_cast<std::size_t>(y) * w + x0;
      auto load = [](const std::int32_t* p) {
        return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
      };
      const __m128i r = load(row);
      auto other = [&](__m128i o) {  // o >= 0 and o != r, lane by lane
        return _mm_andnot_si128(_mm_cmpeq_epi32(o, r), _mm_cmpgt_epi32(o, none));
      };
      const __m128i any = _mm_or_si128(_mm_or_si128(other(load(row - 1)), other(load(row + 1))),
                                       _mm_or_si128(other(load(row - w)), other(load(row + w))));
      const __m128i found = _mm_and_si128(_mm_and_si128(any, _mm_cmpgt_epi32(r, none)), in_block);
      if (_mm_movemask_epi8(found) == 0) continue;
      for (int x = x0; x < x1; ++x) ScanPixel<false>(x, y);
    }
  }
#endif

  const std::vector<std::int32_t>& labels_;
  int width_, height_;
  std::vector<char> listed_;
  std::uint64_t last_pair_ = ~std::uint64_t{0};
  RegionBorders borders_;
};

/// One pass over a whole region-index image (PBRG; GBRG gathers the same grid by grid): the
/// borders between regions and, when `rays` is not null, every region's ray sums.
RegionBorders ScanLabelImage(const datasets::OrganizedCloud& cloud,
                             const std::vector<std::int32_t>& labels, std::size_t num_regions,
                             const DetectionParams& params, std::vector<RaySums>* rays);

/// Merges regions that describe one plane: touching ones (`touching_pairs`, from
/// RegionBorders) and, with params.merge_disjoint, also ones that do not touch; the test is
/// normals within merge_angle_deg and MSE of the union below epsilon (of the union's noise).
/// Pairs are tried in order of increasing union MSE (deterministic; ties by region indices); a
/// merged region keeps the smaller index. `labels` holds region indices (-1 none) and is
/// rewritten; merged-away regions get k = 0 in `regions`, and their ray sums (when `rays` is
/// not empty) move with their moments. With `label_root`, `labels` is left as it is and the map
/// from a label l to its merged region, (*label_root)[l + 1], is written there instead (empty
/// when nothing merged), for FinalizeSegmentation, which rewrites every label anyway: a pass over
/// a pixel image less.
void MergeCoplanarRegions(std::vector<std::int32_t>& labels,
                          const std::vector<std::uint64_t>& touching_pairs,
                          std::vector<MomentSums>& regions, std::vector<RaySums>& rays,
                          const DetectionParams& params,
                          std::vector<std::int32_t>* label_root = nullptr);

/// Builds the output: one Plane per region with k >= 3 (sorted by point count descending, then by
/// region index), covariance from the region noise, and `region_labels` rewritten to plane ids
/// (>= 1) or -1 and moved to out.labels (it is left holding out.labels' former contents).
/// The plane is the eigen fit of the region's moments, or with params.ray_fit the inverse-depth
/// fit of its ray sums `rays` (the eigen fit where that is degenerate).
/// The ray fit also lets the pixels of `border_pixels` change region at a crease, updating
/// `region_labels`, `regions` and `rays` (see FitAlongRays in the source).
/// With `fit_sums` (a grower whose labels are coarser than pixels, GBRG without pixel-level
/// refinement) a region's plane is fitted to the subset of its points summed there instead, along
/// the rays from `fit_rays` with params.ray_fit, and no pixel changes region at a crease;
/// `region_labels` may then be an image of grids, and `border_pixels` is not used. `fit_sums` may
/// be `&regions` (and `fit_rays` `&rays`): every point is fitted, with no second eigen fit.
/// `label_root` (from MergeCoplanarRegions; empty: none) maps each label of `region_labels` to
/// its region first.
void FinalizeSegmentation(const datasets::OrganizedCloud& cloud,
                          std::vector<std::int32_t>& region_labels,
                          std::vector<MomentSums>& regions, std::vector<RaySums>& rays,
                          const std::vector<std::size_t>& border_pixels,
                          const DetectionParams& params, Segmentation& out,
                          const std::vector<MomentSums>* fit_sums = nullptr,
                          const std::vector<RaySums>* fit_rays = nullptr,
                          const std::vector<std::int32_t>& label_root = {});

/// The whole of what follows growth for a grower that has only a region-index image (PBRG):
/// ScanLabelImage, then MergeCoplanarRegions (params.merge_regions), then FinalizeSegmentation.
void FinalizeLabelImage(const datasets::OrganizedCloud& cloud, std::vector<std::int32_t>& labels,
                        std::vector<MomentSums>& regions, const DetectionParams& params,
                        Segmentation& out);

}  // namespace planeslam::detection::internal

#include "region_common.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <tuple>
#include <utility>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/detection/plane_covariance.hpp"

namespace planeslam::detection::internal {
namespace {

/// Solves the ray fit (n = m / |m|, d = 1 / |m| > 0); false when its system is singular (rays
/// spanning a line) or the result is not finite (the caller keeps the eigen fit).
bool SolveRayFit(const RaySums& t, Eigen::Vector3d& normal, double& d) {
  Eigen::Matrix3d A;
  A << t.a00, t.a01, t.a02, t.a01, t.a11, t.a12, t.a02, t.a12, t.a22;
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(A);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return false;
  // Relative pivot check: rays spanning a line (or a point) leave the plane undetermined.
  const Eigen::Vector3d pivots = ldlt.vectorD();
  if (!(pivots.minCoeff() > 1e-12 * pivots.maxCoeff())) return false;
  const Eigen::Vector3d m = ldlt.solve(Eigen::Vector3d(t.b0, t.b1, t.b2));
  const double len = m.norm();
  if (!std::isfinite(len) || !(len > 0.0)) return false;
  normal = m / len;
  d = 1.0 / len;
  return true;
}

/// The depth (or range) s_plane at which the ray of point p, measured at s, meets the plane;
/// false when it does not meet the plane in front of the sensor.
bool DepthOnPlane(const Eigen::Vector3d& p, double s, const RayPlane& plane, double& s_plane) {
  const double np = plane.normal.dot(p);
  if (!(np > 0.0)) return false;
  s_plane = plane.d * s / np;
  return true;
}

}  // namespace

RayPlane SolveRegion(const RaySums& sums, const MomentSums& region) {
  RayPlane plane;
  plane.ok = region.k >= 3 && SolveRayFit(sums, plane.normal, plane.d);
  if (plane.ok) plane.centroid = region.Centroid();
  return plane;
}

bool WithinCreaseGate(const Eigen::Vector3d& p, double s, const RayPlane& other,
                      const DetectionParams& params, double* s_other) {
  if (!DepthOnPlane(p, s, other, *s_other)) return false;
  const double sigma = params.Sigma(s);
  return !(sigma > 0.0 && std::abs(*s_other - s) > kCreaseGateSigmas * sigma);
}

bool SeesOther(const Eigen::Vector3d& p, double s, double s_other, const RayPlane& own,
               const RayPlane& other) {
  double s_own;
  if (!DepthOnPlane(p, s, own, s_own)) return false;
  // Signed offsets of each region's centroid from the other's plane (< 0: on the sensor side).
  const double own_vs_other = other.normal.dot(own.centroid) - other.d;
  const double other_vs_own = own.normal.dot(other.centroid) - own.d;
  if (own_vs_other < 0.0 && other_vs_own < 0.0) return s_other < s_own;  // concave
  if (own_vs_other > 0.0 && other_vs_own > 0.0) return s_other > s_own;  // convex
  return std::abs(s_other - s) < std::abs(s_own - s);
}

bool VisibleHere(const Eigen::Vector3f& p, double s, const RayPlane& own, const RayPlane& other,
                 const DetectionParams& params) {
  // The gate on `other` first, which turns most pixels away before `own`'s depth is worked out.
  const Eigen::Vector3d pd = p.cast<double>();
  double s_other;
  return WithinCreaseGate(pd, s, other, params, &s_other) && SeesOther(pd, s, s_other, own, other);
}

CreaseEvidence NeighbourhoodEvidence(const datasets::OrganizedCloud& cloud, int x, int y,
                                     bool spherical, const RayPlane& own, const RayPlane& other,
                                     const DetectionParams& params) {
  // The mean point of the valid pixels of the 3x3 window, and how far along its ray each plane
  // lies from it: the noise of a mean of n points is sigma / sqrt(n), so the window tells apart
  // planes a single pixel's depth cannot. Float: the offsets meet millimetres of noise.
  Eigen::Vector3f sum = Eigen::Vector3f::Zero();
  float sigma2 = 0.0f;
  int n = 0;
  const int u0 = std::max(x - 1, 0), u1 = std::min(x + 1, cloud.width - 1);
  for (int v = std::max(y - 1, 0); v <= std::min(y + 1, cloud.height - 1); ++v) {
    const Eigen::Vector3f* row = cloud.points.data() + static_cast<std::size_t>(v) * cloud.width;
    for (int u = u0; u <= u1; ++u) {
      const Eigen::Vector3f& q = row[u];
      // An invalid point has a non-finite z, which fails the comparison.
      const float s = PointDepth(q, spherical);
      if (!(s > 0.0f)) continue;
      sum += q;
      const float sigma = params.Sigma(s);
      sigma2 += sigma * sigma;
      ++n;
    }
  }
  constexpr int kMinPixels = 5;
  if (n < kMinPixels || !(sigma2 > 0.0f)) return CreaseEvidence::kUndecided;
  const Eigen::Vector3f mean = sum / static_cast<float>(n);
  const float s = PointDepth(mean, spherical);
  const float np_own = own.normal.cast<float>().dot(mean);
  const float np_other = other.normal.cast<float>().dot(mean);
  if (!(s > 0.0f && np_own > 0.0f && np_other > 0.0f)) return CreaseEvidence::kUndecided;
  // Within kCreaseGateSigmas sqrt(sum sigma^2) / n of each plane along the ray.
  const float gate = static_cast<float>(kCreaseGateSigmas) * std::sqrt(sigma2) / n;
  const bool fits_own = std::abs(s * (static_cast<float>(own.d) / np_own - 1.0f)) <= gate;
  const bool fits_other = std::abs(s * (static_cast<float>(other.d) / np_other - 1.0f)) <= gate;
  if (fits_own == fits_other) return CreaseEvidence::kUndecided;
  return fits_own ? CreaseEvidence::kOwn : CreaseEvidence::kOther;
}

double RayOffset(const Eigen::Vector3f& p, double s, const RayPlane& plane) {
  double s_plane;
  if (!DepthOnPlane(p.cast<double>(), s, plane, s_plane)) {
    return std::numeric_limits<double>::infinity();
  }
  return std::abs(s_plane - s);
}

namespace {

/// How many candidates ahead the crease passes prefetch a pixel's point and labels.
constexpr std::size_t kCreasePrefetchAhead = 8;

int Find(std::vector<int>& parent, int a) {
  while (parent[a] != a) {
    parent[a] = parent[parent[a]];
    a = parent[a];
  }
  return a;
}

/// Calls visit(i) for every pixel i of no region (label < 0) 4-adjacent to a pixel of one, in
/// pixel order. Most pixels have a region: four labels at a time (SSE2) are passed over when none
/// is negative, a third of the time of a pass pixel by pixel.
template <typename Visit>
void ForEachUnassignedBesideRegion(const std::vector<std::int32_t>& labels, int width, int height,
                                   const Visit& visit) {
  auto scalar = [&](int x, int y) {
    const std::size_t i = static_cast<std::size_t>(y) * width + x;
    if (labels[i] >= 0) return;
    if ((x > 0 && labels[i - 1] >= 0) || (x + 1 < width && labels[i + 1] >= 0) ||
        (y > 0 && labels[i - width] >= 0) || (y + 1 < height && labels[i + width] >= 0)) {
      visit(i);
    }
  };
  auto load = [](const std::int32_t* p) {
    return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
  };
  auto sign_bits = [](__m128i v) { return _mm_movemask_ps(_mm_castsi128_ps(v)); };
  for (int y = 0; y < height; ++y) {
    const std::int32_t* row = labels.data() + static_cast<std::size_t>(y) * width;
    int x = 0;
    if (y > 0 && y + 1 < height) {
      // Inside the image: pixels x .. x + 3 with x >= 1 and x + 4 < width, so that the loads one
      // to the left and one to the right stay in the row.
      scalar(0, y);
      for (x = 1; x + 4 < width; x += 4) {
        const int unassigned = sign_bits(load(row + x));
        if (unassigned == 0) continue;
        // A neighbour has a region where its label is >= 0: the AND of the four labels is then
        // >= 0 (sign bit clear) wherever any of them has one.
        const __m128i all_none =
            _mm_and_si128(_mm_and_si128(load(row + x - 1), load(row + x + 1)),
                          _mm_and_si128(load(row + x - width), load(row + x + width)));
        int hits = unassigned & ~sign_bits(all_none);
        while (hits != 0) {
          const int b = __builtin_ctz(hits);
          hits &= hits - 1;
          visit(static_cast<std::size_t>(y) * width + x + b);
        }
      }
    }
    for (; x < width; ++x) scalar(x, y);
  }
}

/// The ray fit of every region (see DetectionParams::ray_fit), in two steps.
/// 1. Fit each region along the rays, from its ray sums `sums`.
/// 2. Crease competition (up to kCreasePasses passes, the first over `border_pixels` and the
///    valid pixels of no region beside one): a pixel 4-adjacent to another region, within
///    kCreaseGateSigmas sigma(s) of its plane, moves there when its 3x3 window lies on that
///    plane and off its own (NeighbourhoodEvidence), or, where the window fits both or
///    neither, when VisibleHere says its ray sees that region's surface; a pixel of no region joins
///    the neighbouring region whose plane passes within kCreaseGateSigmas sigma(s) of it along
///    the ray (the nearest); the regions that changed
///    are fitted again, and the next pass looks only around the pixels that moved. Growth admits
///    a pixel by the paper's orthogonal distance, gamma + gamma_sigmas sigma_n, so at a crease a
///    region takes a strip of the neighbouring surface as wide as the noise; on a narrow or
///    grazing plane (a door jamb, a wall seen along) that strip tilts the normal by up to a
///    degree under Kinect noise; the competition hands the strip back.
/// Moved pixels leave and join the region moments and ray sums too, so all that is reported of a
/// plane describes its final pixels.
std::vector<RayPlane> FitAlongRays(const datasets::OrganizedCloud& cloud,
                                   std::vector<std::int32_t>& labels,
                                   const std::int32_t* label_root, std::vector<MomentSums>& regions,
                                   std::vector<RaySums>& sums,
                                   const std::vector<std::size_t>& border_pixels,
                                   const DetectionParams& params) {
  constexpr int kCreasePasses = 3;
  PLANESLAM_CHECK(sums.size() == regions.size(), "ray fit: one RaySums per region expected");
  const bool spherical = cloud.model == datasets::SensorModel::kSpherical;
  const int width = cloud.width, height = cloud.height;
  auto weight = [&](double s) { return params.RayFitWeight(s); };
  const double inv_width = 1.0 / std::max(width, 1);
  // The first crease pass visits the pixels on a border between two regions.
  std::vector<std::size_t> candidates = border_pixels;
  std::vector<char> queued(labels.size(), 0);
  for (const std::size_t i : candidates) queued[i] = 1;
  auto enqueue = [&](std::size_t i) {
    if (!queued[i]) candidates.push_back(i);
    queued[i] = 1;
  };
  std::vector<RayPlane> planes(regions.size());
  for (std::size_t r = 0; r < regions.size(); ++r) planes[r] = SolveRegion(sums[r], regions[r]);
  // A label's region: through label_root (shifted by one, so that -1 maps to -1) after a merge
  // that left the labels as they were. A region a pixel moves to is a root: it maps to itself.
  auto region_of = [&](std::size_t i) { return label_root[labels[i] + 1]; };

  // Pixel i's region after this pass (its own when it stays).
  auto competitor = [&](std::size_t i) -> std::int32_t {
    const std::int32_t r = region_of(i);
    if (r >= 0 && !planes[r].ok) return r;
    // A point behind the sensor (possible in a PCD) never entered the ray sums: it stays.
    const double s = PointDepth(cloud.points[i], spherical);
    if (!(s > 0.0)) return r;
    // The pixel's row and column without an integer division: (i + 0.5) / width is at least
    // 0.5 / width from an integer, far beyond the product's rounding.
    const int y = static_cast<int>((static_cast<double>(i) + 0.5) * inv_width);
    const int x = static_cast<int>(i) - y * width;
    const std::int32_t around[4] = {
        x > 0 ? region_of(i - 1) : -1, x + 1 < width ? region_of(i + 1) : -1,
        y > 0 ? region_of(i - width) : -1, y + 1 < height ? region_of(i + width) : -1};
    if (r < 0) {
      // A pixel of no region: to the neighbouring region whose plane passes nearest its point
      // along the ray, within the gate.
      std::int32_t best = -1;
      double best_offset = kCreaseGateSigmas * params.Sigma(s);
      for (const std::int32_t other : around) {
        if (other < 0 || !planes[other].ok) continue;
        // Only into a hole or a notch of the region (two of the four sides or more): a pixel on
        // its straight rim may be a strip of an undetected surface beside it, which would tilt
        // it.
        int sides = 0;
        for (const std::int32_t o : around) sides += o == other;
        if (sides < 2) continue;
        const double offset = RayOffset(cloud.points[i], s, planes[other]);
        if (offset < best_offset) {
          best_offset = offset;
          best = other;
        }
      }
      return best;
    }
    for (int a = 0; a < 4; ++a) {
      const std::int32_t other = around[a];
      if (other < 0 || other == r || !planes[other].ok) continue;
      // A region met twice (left and above, say) gets the same answer twice: asked once.
      bool asked = false;
      for (int b = 0; b < a; ++b) asked |= around[b] == other;
      if (asked) continue;
      // Only a pixel within the noise of `other`'s plane may move. Its window decides where it
      // can: a pixel near the line where two planes meet fits both, and a band of one surface
      // along that line, beyond where the other surface ends, would tilt the other's plane.
      // Visibility decides where the window fits both or neither (a window across a depth edge).
      const Eigen::Vector3d p = cloud.points[i].cast<double>();
      double s_other;
      if (!WithinCreaseGate(p, s, planes[other], params, &s_other)) continue;
      const CreaseEvidence evidence =
          NeighbourhoodEvidence(cloud, x, y, spherical, planes[r], planes[other], params);
      if (evidence == CreaseEvidence::kOther) return other;
      if (evidence == CreaseEvidence::kUndecided &&
          SeesOther(p, s, s_other, planes[r], planes[other])) {
        return other;
      }
    }
    return r;
  };
  // And the pixels of no region beside one (an invalid one is turned away by its depth). Growth and
  // the pixel-level refinement turned them away by their distance to the eigen fit, which on a
  // surface seen at a grazing angle is tilted (see ray_fit): away from it, they are the pixels on
  // one side of the true plane, and without them the ray fit is tilted too (most on a narrow
  // wall seen at a grazing angle, by centimetres).
  ForEachUnassignedBesideRegion(labels, width, height, enqueue);
  std::vector<char> touched(regions.size(), 0);
  std::vector<std::pair<std::size_t, std::int32_t>> moves;
  for (int pass = 0; pass < kCreasePasses && !candidates.empty(); ++pass) {
    // Decide every move of the pass on the same planes, then apply them.
    moves.clear();
    const std::size_t num_candidates = candidates.size();
    for (std::size_t j = 0; j < num_candidates; ++j) {
      const std::size_t i = candidates[j];
      // The candidates lie scattered over a cloud that has mostly left the caches since growth
      // read it: fetch the point and the labels around it a few candidates ahead.
      if (j + kCreasePrefetchAhead < num_candidates) {
        const std::size_t ahead = candidates[j + kCreasePrefetchAhead];
        __builtin_prefetch(&cloud.points[ahead]);
        __builtin_prefetch(&labels[ahead]);
        if (ahead >= static_cast<std::size_t>(width)) __builtin_prefetch(&labels[ahead - width]);
        if (ahead + width < labels.size()) __builtin_prefetch(&labels[ahead + width]);
      }
      queued[i] = 0;
      const std::int32_t to = competitor(i);
      if (to != region_of(i)) moves.emplace_back(i, to);
    }
    candidates.clear();
    for (const auto& [i, to] : moves) {
      const std::int32_t from = region_of(i);
      const Eigen::Vector3f& p = cloud.points[i];
      const float s = PointDepth(p, spherical);
      MomentSums point;
      point.Add(p.x(), p.y(), p.z(), params.NoiseWeight(s));
      if (from >= 0) {
        regions[from].Subtract(point);
        sums[from].Add(p, s, -weight(s));
        touched[from] = 1;
      }
      regions[to].Merge(point);
      sums[to].Add(p, s, weight(s));
      touched[to] = 1;
      labels[i] = to;
      const std::size_t x = i % width;
      if (x > 0) enqueue(i - 1);
      if (x + 1 < static_cast<std::size_t>(width)) enqueue(i + 1);
      if (i >= static_cast<std::size_t>(width)) enqueue(i - width);
      if (i + width < labels.size()) enqueue(i + width);
    }
    for (std::size_t r = 0; r < regions.size(); ++r) {
      if (!touched[r]) continue;
      planes[r] = SolveRegion(sums[r], regions[r]);
      touched[r] = 0;
    }
  }
  return planes;
}

}  // namespace

RegionBorderScan::RegionBorderScan(const std::vector<std::int32_t>& labels, int width, int height)
    : labels_(labels), width_(width), height_(height), listed_(labels.size(), 0) {}

void RegionBorderScan::Add(std::size_t i, std::int32_t r, std::size_t j) {
  const std::int32_t other = labels_[j];
  // Both sides: j may lie outside the scanned part (an interior grid of GBRG).
  for (const std::size_t b : {i, j}) {
    if (!listed_[b]) borders_.pixels.push_back(b);
    listed_[b] = 1;
  }
  // A border repeats the same pair along its length: skip a pair equal to the last one, so the
  // list to sort holds about one entry per border run, not one per pixel.
  const auto lo = static_cast<std::uint64_t>(std::min(r, other));
  const auto hi = static_cast<std::uint64_t>(std::max(r, other));
  const std::uint64_t key = lo << 32 | hi;
  if (key != last_pair_) borders_.pairs.push_back(key);
  last_pair_ = key;
}

RegionBorders RegionBorderScan::Finish() {
  std::sort(borders_.pairs.begin(), borders_.pairs.end());
  borders_.pairs.erase(std::unique(borders_.pairs.begin(), borders_.pairs.end()),
                       borders_.pairs.end());
  return std::move(borders_);
}

namespace {

/// Every region's ray sums from a region-index image: runs of one label are summed locally and
/// flushed when the label changes. A loop of its own, with no call in it, so that the run's nine
/// sums stay in registers (beside the border scan's calls they would live on the stack: a load
/// and a store per sum and pixel).
template <bool kSpherical>
void SumRaysByLabel(const datasets::OrganizedCloud& cloud, const std::vector<std::int32_t>& labels,
                    const DetectionParams& params, std::vector<RaySums>& rays) {
  RaySums run;
  std::int32_t run_label = -1;
  const std::size_t num_pixels = labels.size();
  for (std::size_t i = 0; i < num_pixels; ++i) {
    const std::int32_t r = labels[i];
    if (r < 0) continue;
    if (r != run_label) {
      if (run_label >= 0) rays[run_label].Add(run);
      run = RaySums();
      run_label = r;
    }
    // A point behind the sensor (possible in a PCD) has no ray fit weight.
    const float s = PointDepth(cloud.points[i], kSpherical);
    if (s > 0.0f) run.Add(cloud.points[i], s, params.RayFitWeight(s));
  }
  if (run_label >= 0) rays[run_label].Add(run);
}

}  // namespace

RegionBorders ScanLabelImage(const datasets::OrganizedCloud& cloud,
                             const std::vector<std::int32_t>& labels, std::size_t num_regions,
                             const DetectionParams& params, std::vector<RaySums>* rays) {
  const int width = cloud.width, height = cloud.height;
  if (rays) {
    rays->assign(num_regions, RaySums());
    if (cloud.model == datasets::SensorModel::kSpherical) {
      SumRaysByLabel<true>(cloud, labels, params, *rays);
    } else {
      SumRaysByLabel<false>(cloud, labels, params, *rays);
    }
  }
  RegionBorderScan borders(labels, width, height);
  const std::int32_t* const label = labels.data();
  // Right and down neighbours: every 4-adjacent pair of pixels once, in pixel order.
  auto scan_pixel = [&](int x, int y) {
    const std::size_t i = static_cast<std::size_t>(y) * width + x;
    const std::int32_t r = label[i];
    if (r < 0) return;
    if (x + 1 < width && label[i + 1] >= 0 && label[i + 1] != r) borders.Add(i, r, i + 1);
    if (y + 1 < height && label[i + width] >= 0 && label[i + width] != r) {
      borders.Add(i, r, i + width);
    }
  };
  auto load = [](const std::int32_t* p) {
    return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
  };
  const __m128i none = _mm_set1_epi32(-1);
  for (int y = 0; y < height; ++y) {
    int x = 0;
    if (y + 1 < height) {
      // Four pixels at a time (SSE2), passed over when none of them has a pixel of another
      // region to its right or below (most pixels: inside a region, or in none): x + 4 < width
      // keeps the loads one to the right in the row.
      const std::int32_t* row = label + static_cast<std::size_t>(y) * width;
      for (; x + 4 < width; x += 4) {
        const __m128i r = load(row + x);
        auto other = [&](__m128i o) {  // o >= 0 and o != r, lane by lane
          return _mm_andnot_si128(_mm_cmpeq_epi32(o, r), _mm_cmpgt_epi32(o, none));
        };
        const __m128i found = _mm_and_si128(
            _mm_or_si128(other(load(row + x + 1)), other(load(row + x + width))),
            _mm_cmpgt_epi32(r, none));
        if (_mm_movemask_epi8(found) == 0) continue;
        for (int j = x; j < x + 4; ++j) scan_pixel(j, y);
      }
    }
    for (; x < width; ++x) scan_pixel(x, y);
  }
  return borders.Finish();
}

void MergeCoplanarRegions(std::vector<std::int32_t>& labels,
                          const std::vector<std::uint64_t>& touching_pairs,
                          std::vector<MomentSums>& regions, std::vector<RaySums>& rays,
                          const DetectionParams& params, std::vector<std::int32_t>* label_root) {
  if (label_root != nullptr) label_root->clear();
  const int n = static_cast<int>(regions.size());
  if (n < 2) return;
  const std::vector<std::uint64_t>& pairs = touching_pairs;
  const double cos_merge = std::cos(params.merge_angle_deg * M_PI / 180.0);
  std::vector<FastFit> fits(n);
  for (int i = 0; i < n; ++i) fits[i] = FitSums(regions[i]);
  // One plane: normals within the merge angle and the union's MSE within epsilon of its noise.
  // Regions that do not touch must also each lie on the union's plane: their mean offset from it
  // within gamma. (The MSE test alone lets two parallel surfaces a few centimetres apart merge at
  // 4 m, where the per-point noise is 2 cm; touching regions are held together by their border.)
  auto one_plane = [&](const MomentSums& ra, const FastFit& fa, const MomentSums& rb,
                       const FastFit& fb, bool touching, double* mse) {
    if (std::abs(fa.normal.dot(fb.normal)) < cos_merge) return false;
    MomentSums u = ra;
    u.Merge(rb);
    const FastFit fu = FitSums(u);
    if (fu.mse >= params.Epsilon(u.ExpectedMse(fu.normal), u.k)) return false;
    if (!touching) {
      if (std::abs(fu.normal.dot(ra.Centroid()) - fu.d) > params.gamma) return false;
      if (std::abs(fu.normal.dot(rb.Centroid()) - fu.d) > params.gamma) return false;
    }
    *mse = fu.mse;
    return true;
  };
  // Candidate pairs ordered by the MSE of their union (the most obviously one surface first).
  std::vector<std::tuple<double, int, int, bool>> cand;
  auto consider = [&](int a, int b, bool touching) {
    if (regions[a].k < 3 || regions[b].k < 3) return;
    double mse = 0.0;
    if (one_plane(regions[a], fits[a], regions[b], fits[b], touching, &mse)) {
      cand.emplace_back(mse, a, b, touching);
    }
  };
  for (std::uint64_t key : pairs) {
    consider(static_cast<int>(key >> 32), static_cast<int>(key & 0xffffffffu), true);
  }
  if (params.merge_disjoint) {
    // Regions that do not touch can still be one plane: a floor or wall seen on both sides of an
    // occluder.
    for (int a = 0; a < n; ++a) {
      for (int b = a + 1; b < n; ++b) {
        const std::uint64_t key =
            static_cast<std::uint64_t>(a) << 32 | static_cast<std::uint64_t>(b);
        if (!std::binary_search(pairs.begin(), pairs.end(), key)) consider(a, b, false);
      }
    }
  }
  if (cand.empty()) return;
  std::sort(cand.begin(), cand.end());
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  bool merged_any = false;
  for (const auto& [mse0, a0, b0, touching] : cand) {
    (void)mse0;
    int a = Find(parent, a0), b = Find(parent, b0);
    if (a == b) continue;
    if (b < a) std::swap(a, b);
    // Re-test with the current (possibly already merged) regions.
    double mse = 0.0;
    if (!one_plane(regions[a], FitSums(regions[a]), regions[b], FitSums(regions[b]), touching,
                   &mse)) {
      continue;
    }
    regions[a].Merge(regions[b]);
    regions[b] = MomentSums();
    if (!rays.empty()) {
      rays[a].Add(rays[b]);
      rays[b] = RaySums();
    }
    parent[b] = a;
    merged_any = true;
  }
  if (!merged_any) return;
  // Every label to its region's root, through a table shifted by one so that -1 (no region) maps
  // to itself without a branch.
  std::vector<std::int32_t> root(static_cast<std::size_t>(n) + 1, -1);
  for (int i = 0; i < n; ++i) root[static_cast<std::size_t>(i) + 1] = Find(parent, i);
  if (label_root != nullptr) {
    label_root->swap(root);
  } else {
    MapLabels(root.data(), labels.data(), labels.data(), labels.size());
  }
}

void FinalizeSegmentation(const datasets::OrganizedCloud& cloud,
                          std::vector<std::int32_t>& region_labels,
                          std::vector<MomentSums>& regions, std::vector<RaySums>& rays,
                          const std::vector<std::size_t>& border_pixels,
                          const DetectionParams& params, Segmentation& out,
                          const std::vector<MomentSums>* fit_sums,
                          const std::vector<RaySums>* fit_rays,
                          const std::vector<std::int32_t>& label_root) {
  out.width = cloud.width;
  out.height = cloud.height;
  const int n = static_cast<int>(regions.size());
  PLANESLAM_CHECK(label_root.empty() || label_root.size() == regions.size() + 1,
                  "finalize: a label map of one entry per region and -1 expected");
  // Each label's region (shifted by one: -1 maps to -1): label_root, or the identity.
  std::vector<std::int32_t> root = label_root;
  if (root.empty()) {
    root.resize(static_cast<std::size_t>(n) + 1);
    std::iota(root.begin(), root.end(), -1);
  }
  PLANESLAM_CHECK(
      fit_sums == nullptr ||
          (fit_sums->size() == regions.size() &&
           (!params.ray_fit || (fit_rays != nullptr && fit_rays->size() == regions.size()))),
      "finalize: one fit subset per region expected");
  std::vector<RayPlane> ray_planes;
  if (params.ray_fit && fit_sums != nullptr) {
    ray_planes.resize(regions.size());
    for (std::size_t r = 0; r < regions.size(); ++r) {
      ray_planes[r] = SolveRegion((*fit_rays)[r], (*fit_sums)[r]);
    }
  } else if (params.ray_fit) {
    ray_planes =
        FitAlongRays(cloud, region_labels, root.data(), regions, rays, border_pixels, params);
  }
  std::vector<int> order;
  order.reserve(n);
  for (int i = 0; i < n; ++i) {
    if (regions[i].k >= 3) order.push_back(i);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return regions[a].k > regions[b].k; });
  std::vector<std::int32_t> id_of(static_cast<std::size_t>(n) + 1, -1);  // region + 1 -> plane id
  out.planes.clear();
  out.planes.reserve(order.size());
  for (int r : order) {
    const MomentSums& s = regions[r];
    const FastFit f = FitSums(s);
    Plane p;
    p.id = static_cast<int>(out.planes.size()) + 1;
    p.normal = f.normal;
    p.d = f.d;
    if (params.ray_fit && ray_planes[static_cast<std::size_t>(r)].ok) {
      p.normal = ray_planes[static_cast<std::size_t>(r)].normal;
      p.d = ray_planes[static_cast<std::size_t>(r)].d;
    } else if (fit_sums != nullptr && fit_sums != &regions &&
               (*fit_sums)[static_cast<std::size_t>(r)].k >= 3) {
      const FastFit subset = FitSums((*fit_sums)[static_cast<std::size_t>(r)]);
      p.normal = subset.normal;
      p.d = subset.d;
    }
    p.centroid = f.centroid;
    p.point_count = static_cast<std::int64_t>(std::llround(s.k));
    p.mse = f.mse;
    p.eigenvalues = Eigen::Vector3d(f.l1, f.l2, f.l3);
    p.moments = s.ToPlaneMoments();
    // Per-point variance along the normal: the sensor model's expected MSE of the region's
    // points, or the observed MSE when larger (unmodelled roughness), never below (0.1 mm)^2.
    const double sigma2 = std::max({s.ExpectedMse(p.normal), f.mse, 1e-8});
    p.covariance = PlaneCovariance(p.moments, p.normal, sigma2);
    id_of[static_cast<std::size_t>(r) + 1] = p.id;
    out.planes.push_back(std::move(p));
  }
  // Rewritten in place and handed over: no second image to allocate and fill with zeros first.
  // One pass for both maps: label -> region -> plane id.
  for (std::int32_t& entry : root) entry = id_of[static_cast<std::size_t>(entry + 1)];
  MapLabels(root.data(), region_labels.data(), region_labels.data(), region_labels.size());
  out.labels.swap(region_labels);
}

void FinalizeLabelImage(const datasets::OrganizedCloud& cloud, std::vector<std::int32_t>& labels,
                        std::vector<MomentSums>& regions, const DetectionParams& params,
                        Segmentation& out) {
  // Region borders (merge candidates, crease pixels) and ray sums from one look at every pixel.
  RegionBorders borders;
  std::vector<RaySums> rays;
  if (params.merge_regions || params.ray_fit) {
    borders =
        ScanLabelImage(cloud, labels, regions.size(), params, params.ray_fit ? &rays : nullptr);
  }
  std::vector<std::int32_t> label_root;  // the merge's, applied with the plane ids
  if (params.merge_regions) {
    MergeCoplanarRegions(labels, borders.pairs, regions, rays, params, &label_root);
  }
  FinalizeSegmentation(cloud, labels, regions, rays, borders.pixels, params, out, nullptr, nullptr,
                       label_root);
}

}  // namespace planeslam::detection::internal

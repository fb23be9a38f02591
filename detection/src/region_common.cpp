#include "region_common.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <tuple>

#include "planeslam/detection/plane_covariance.hpp"

namespace planeslam::detection::internal {
namespace {

int Find(std::vector<int>& parent, int a) {
  while (parent[a] != a) {
    parent[a] = parent[parent[a]];
    a = parent[a];
  }
  return a;
}

}  // namespace

void MergeCoplanarRegions(std::vector<std::int32_t>& labels, int width, int height,
                          std::vector<MomentSums>& regions, const DetectionParams& params) {
  const int n = static_cast<int>(regions.size());
  if (n < 2) return;
  // Adjacent pairs from right and down neighbours, packed into 64-bit keys, sorted unique.
  // A border between two regions repeats the same pair along its length: skip a pair equal to the
  // last one recorded, so the list to sort is about one entry per border run, not per pixel.
  std::vector<std::uint64_t> pairs;
  std::uint64_t last = ~std::uint64_t{0};
  auto record = [&](std::int32_t a, std::int32_t b) {
    const auto lo = static_cast<std::uint64_t>(std::min(a, b));
    const auto hi = static_cast<std::uint64_t>(std::max(a, b));
    const std::uint64_t key = lo << 32 | hi;
    if (key != last) pairs.push_back(key);
    last = key;
  };
  for (int y = 0; y < height; ++y) {
    const std::int32_t* row = labels.data() + static_cast<std::size_t>(y) * width;
    const std::int32_t* below = y + 1 < height ? row + width : nullptr;
    for (int x = 0; x < width; ++x) {
      const std::int32_t a = row[x];
      if (a < 0) continue;
      if (x + 1 < width && row[x + 1] >= 0 && row[x + 1] != a) record(a, row[x + 1]);
      if (below && below[x] >= 0 && below[x] != a) record(a, below[x]);
    }
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
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
    if (fu.mse >= params.Epsilon(u.ExpectedMse(fu.normal))) return false;
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
        const std::uint64_t key = static_cast<std::uint64_t>(a) << 32 | static_cast<std::uint64_t>(b);
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
    parent[b] = a;
    merged_any = true;
  }
  if (!merged_any) return;
  for (auto& l : labels) {
    if (l >= 0) l = Find(parent, l);
  }
}

void FinalizeSegmentation(const std::vector<std::int32_t>& region_labels, int width, int height,
                          const std::vector<MomentSums>& regions, Segmentation& out) {
  out.width = width;
  out.height = height;
  const int n = static_cast<int>(regions.size());
  std::vector<int> order;
  order.reserve(n);
  for (int i = 0; i < n; ++i) {
    if (regions[i].k >= 3) order.push_back(i);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return regions[a].k > regions[b].k; });
  std::vector<std::int32_t> id_of(n, -1);
  out.planes.clear();
  out.planes.reserve(order.size());
  for (int r : order) {
    const MomentSums& s = regions[r];
    const FastFit f = FitSums(s);
    Plane p;
    p.id = static_cast<int>(out.planes.size()) + 1;
    p.normal = f.normal;
    p.d = f.d;
    p.centroid = f.centroid;
    p.point_count = static_cast<std::int64_t>(std::llround(s.k));
    p.mse = f.mse;
    p.eigenvalues = Eigen::Vector3d(f.l1, f.l2, f.l3);
    p.moments = s.ToPlaneMoments();
    // Per-point variance along the normal: the sensor model's expected MSE of the region's
    // points, or the observed MSE when larger (unmodelled roughness), never below (0.1 mm)^2.
    const double sigma2 = std::max({s.ExpectedMse(f.normal), f.mse, 1e-8});
    p.covariance = PlaneCovariance(p.moments, p.normal, sigma2);
    id_of[r] = p.id;
    out.planes.push_back(std::move(p));
  }
  out.labels.resize(region_labels.size());
  for (std::size_t i = 0; i < region_labels.size(); ++i) {
    const std::int32_t r = region_labels[i];
    out.labels[i] = r >= 0 ? id_of[r] : -1;
  }
}

}  // namespace planeslam::detection::internal

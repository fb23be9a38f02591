#include "region_common.hpp"

#include <Eigen/Cholesky>
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

/// Normal equations of the ray fit of one region: 1/s_i = m.q_i with q_i = p_i / s_i the ray
/// of pixel i scaled to unit depth (unit range for a scanner) and m = n / d; A = sum w q q^T
/// (upper triangle), b = sum w q / s.
struct RaySums {
  double a00 = 0, a01 = 0, a02 = 0, a11 = 0, a12 = 0, a22 = 0;
  double b0 = 0, b1 = 0, b2 = 0;

  /// Adds pixel p at depth s with weight w (a negative w removes it). The ray is formed in
  /// float (one division; 1e-7 relative, far below the depth noise) and summed in double.
  void Add(const Eigen::Vector3f& p, float s, double w) {
    const float inv_f = 1.0f / s;
    const double inv = inv_f;
    const double qx = p.x() * inv_f, qy = p.y() * inv_f, qz = p.z() * inv_f;
    const double wx = w * qx, wy = w * qy, wz = w * qz;
    a00 += wx * qx;
    a01 += wx * qy;
    a02 += wx * qz;
    a11 += wy * qy;
    a12 += wy * qz;
    a22 += wz * qz;
    b0 += wx * inv;
    b1 += wy * inv;
    b2 += wz * inv;
  }
  void Add(const RaySums& o) {
    a00 += o.a00;
    a01 += o.a01;
    a02 += o.a02;
    a11 += o.a11;
    a12 += o.a12;
    a22 += o.a22;
    b0 += o.b0;
    b1 += o.b1;
    b2 += o.b2;
  }
};

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

RayPlane SolveRegion(const RaySums& sums, const MomentSums& region) {
  RayPlane plane;
  plane.ok = region.k >= 3 && SolveRayFit(sums, plane.normal, plane.d);
  if (plane.ok) plane.centroid = region.Centroid();
  return plane;
}

/// Whether pixel p of region `own` shows region `other`'s surface instead: `other`'s plane is
/// within kCreaseGateSigmas sigma(s) along the ray, and it is the plane the ray sees where the
/// two meet. At a concave crease (each region in front of the other's plane, e.g. a wall corner
/// or a box on the floor) the ray sees the nearer of the two planes; at a convex one (each behind
/// the other's plane, a box's edge) the farther. Where the regions are neither (planes crossing),
/// the nearer along the ray to the measured point wins. The planes come from all the regions'
/// pixels, so where their crease runs is known far better than from any one pixel's depth.
bool VisibleHere(const Eigen::Vector3f& p, double s, const RayPlane& own, const RayPlane& other,
                 const DetectionParams& params) {
  const Eigen::Vector3d pd = p.cast<double>();
  const double np_own = own.normal.dot(pd), np_other = other.normal.dot(pd);
  if (!(np_other > 0.0) || !(np_own > 0.0)) return false;
  // Depths at which the pixel's ray meets each plane.
  const double s_own = own.d * s / np_own, s_other = other.d * s / np_other;
  const double sigma = params.Sigma(s);
  if (sigma > 0.0 && std::abs(s_other - s) > kCreaseGateSigmas * sigma) return false;
  // Signed offsets of each region's centroid from the other's plane (< 0: on the sensor side).
  const double own_vs_other = other.normal.dot(own.centroid) - other.d;
  const double other_vs_own = own.normal.dot(other.centroid) - own.d;
  if (own_vs_other < 0.0 && other_vs_own < 0.0) return s_other < s_own;  // concave
  if (own_vs_other > 0.0 && other_vs_own > 0.0) return s_other > s_own;  // convex
  return std::abs(s_other - s) < std::abs(s_own - s);
}

/// The ray fit of every region (see DetectionParams::ray_fit), in two steps.
/// 1. Fit each region along the rays.
/// 2. Crease competition (up to kCreasePasses passes): a pixel 4-adjacent to another region moves
///    there when VisibleHere says its ray sees that region's surface; the regions that changed
///    are fitted again, and the next pass looks only around the pixels that moved. Growth admits
///    a pixel by the paper's orthogonal distance, gamma + gamma_sigmas sigma_n, so at a crease a
///    region takes a strip of the neighbouring surface as wide as the noise; on a narrow or
///    grazing plane (a door jamb, a wall seen along) that strip tilts the normal by up to a
///    degree (synthetic room, Kinect noise: mean normal error of correct planes 0.157 -> 0.064
///    deg for PBRG, 0.066 -> 0.040 deg for GBRG).
/// Moved pixels leave and join the region moments too, so all that is reported of a plane
/// describes its final pixels.
std::vector<RayPlane> FitAlongRays(const datasets::OrganizedCloud& cloud,
                                   std::vector<std::int32_t>& labels,
                                   std::vector<MomentSums>& regions,
                                   const DetectionParams& params) {
  constexpr int kCreasePasses = 3;
  const bool spherical = cloud.model == datasets::SensorModel::kSpherical;
  const int width = cloud.width, height = cloud.height;
  // A Kinect-type model (sigma0 = 0) weighs every pixel alike; skip the two divisions per pixel.
  const bool uniform_weight = params.sigma0 == 0.0;
  auto weight = [&](double s) { return uniform_weight ? 1.0 : params.InverseDepthWeight(s); };

  // One pass: the ray sums (runs of one label are summed locally and flushed when the label
  // changes) and the pixels on a border between two regions, which the first crease pass visits.
  std::vector<RaySums> sums(regions.size());
  std::vector<std::size_t> candidates;
  std::vector<char> queued(labels.size(), 0);
  auto enqueue = [&](std::size_t i) {
    if (!queued[i]) candidates.push_back(i);
    queued[i] = 1;
  };
  RaySums run;
  std::int32_t run_label = -1;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * width + x;
      const std::int32_t r = labels[i];
      if (r < 0) continue;
      if (r != run_label) {
        if (run_label >= 0) sums[run_label].Add(run);
        run = RaySums();
        run_label = r;
      }
      const float s = PointDepth(cloud.points[i], spherical);
      if (s > 0.0f) run.Add(cloud.points[i], s, weight(s));
      if (x + 1 < width && labels[i + 1] >= 0 && labels[i + 1] != r) {
        enqueue(i);
        enqueue(i + 1);
      }
      if (y + 1 < height && labels[i + width] >= 0 && labels[i + width] != r) {
        enqueue(i);
        enqueue(i + width);
      }
    }
  }
  if (run_label >= 0) sums[run_label].Add(run);
  std::vector<RayPlane> planes(regions.size());
  for (std::size_t r = 0; r < regions.size(); ++r) planes[r] = SolveRegion(sums[r], regions[r]);

  // Pixel i's region after this pass (its own when it stays).
  auto competitor = [&](std::size_t i) -> std::int32_t {
    const std::int32_t r = labels[i];
    if (r < 0 || !planes[r].ok) return r;
    // A point behind the sensor (possible in a PCD) never entered the ray sums: it stays.
    const double s = PointDepth(cloud.points[i], spherical);
    if (!(s > 0.0)) return r;
    const int x = static_cast<int>(i % width), y = static_cast<int>(i / width);
    const std::int32_t around[4] = {x > 0 ? labels[i - 1] : -1, x + 1 < width ? labels[i + 1] : -1,
                                    y > 0 ? labels[i - width] : -1,
                                    y + 1 < height ? labels[i + width] : -1};
    for (const std::int32_t other : around) {
      if (other < 0 || other == r || !planes[other].ok) continue;
      if (VisibleHere(cloud.points[i], s, planes[r], planes[other], params)) return other;
    }
    return r;
  };
  std::vector<char> touched(regions.size(), 0);
  std::vector<std::pair<std::size_t, std::int32_t>> moves;
  for (int pass = 0; pass < kCreasePasses && !candidates.empty(); ++pass) {
    // Decide every move of the pass on the same planes, then apply them.
    moves.clear();
    for (const std::size_t i : candidates) {
      queued[i] = 0;
      const std::int32_t to = competitor(i);
      if (to != labels[i]) moves.emplace_back(i, to);
    }
    candidates.clear();
    for (const auto& [i, to] : moves) {
      const std::int32_t from = labels[i];
      const Eigen::Vector3f& p = cloud.points[i];
      const float s = PointDepth(p, spherical);
      MomentSums point;
      point.Add(p.x(), p.y(), p.z(), params.NoiseWeight(s));
      regions[from].Subtract(point);
      regions[to].Merge(point);
      sums[from].Add(p, s, -weight(s));
      sums[to].Add(p, s, weight(s));
      touched[from] = touched[to] = 1;
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
    parent[b] = a;
    merged_any = true;
  }
  if (!merged_any) return;
  for (auto& l : labels) {
    if (l >= 0) l = Find(parent, l);
  }
}

void FinalizeSegmentation(const datasets::OrganizedCloud& cloud,
                          std::vector<std::int32_t>& region_labels,
                          std::vector<MomentSums>& regions, const DetectionParams& params,
                          Segmentation& out) {
  out.width = cloud.width;
  out.height = cloud.height;
  const int n = static_cast<int>(regions.size());
  const std::vector<RayPlane> ray_planes = params.ray_fit
                                               ? FitAlongRays(cloud, region_labels, regions, params)
                                               : std::vector<RayPlane>();
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
    if (params.ray_fit && ray_planes[static_cast<std::size_t>(r)].ok) {
      p.normal = ray_planes[static_cast<std::size_t>(r)].normal;
      p.d = ray_planes[static_cast<std::size_t>(r)].d;
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

#include "planeslam/detection/point_region_growing.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

#include "planeslam/datasets/errors.hpp"
#include "region_common.hpp"

namespace planeslam::detection {
namespace {

using Clock = std::chrono::steady_clock;

/// How many members ahead in the growth queue PBRG prefetches a pixel's neighbourhood.
constexpr std::size_t kGrowPrefetchAhead = 8;
double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// A pixel's state in Workspace::labels besides its region (>= 0): free (valid, in no region
/// yet), set aside (in a region too small to keep: R', never a seed or a member again), invalid.
/// One load tells a neighbour's state; the set-aside and invalid pixels become kFree (no region)
/// for the output.
constexpr std::int32_t kFree = -1, kSetAside = -2, kInvalid = -3;

struct Workspace {
  std::vector<std::int32_t> labels;  ///< region index (accepted or growing), or a state above
  std::vector<float> rel2;           ///< (sigma(z)/z)^2 per pixel
  std::vector<int> members;
  std::vector<MomentSums> regions;
  std::vector<FastFit> fits;                ///< of accepted regions, at acceptance
  std::vector<std::pair<int, int>> stolen;  ///< (point, previous region) of this growth
};

/// A seed: the point, its window neighbours within delta, and their moments and plane.
struct Seed {
  std::size_t s = 0;
  int nb[8] = {};
  int n_nb = 0;
  MomentSums region;
  FastFit fit;
};

/// What the join tests between refits read of a point set: its moments along the region's
/// current normal n (K, n^T Q n, n.S, n^T W n) and trace(W). Five sums instead of sixteen per
/// join; MomentSums's figures of the same name from them.
struct NormalSums {
  double k = 0, nqn = 0, ns = 0, nwn = 0, trace_w = 0;

  void Set(const MomentSums& m, const Eigen::Vector3d& n) {
    k = m.k;
    m.AlongNormal(n, nqn, ns);
    nwn = m.NoiseAlong(n);
    trace_w = m.wxx + m.wyy + m.wzz;
  }
  /// Adds point p of relative noise w.
  void Add(const Eigen::Vector3d& n, const Eigen::Vector3d& p, double w) { AddAt(n.dot(p), p, w); }
  /// The same, given t = n.p (the join tests have it already).
  void AddAt(double t, const Eigen::Vector3d& p, double w) {
    k += 1.0;
    nqn += t * t;
    ns += t;
    nwn += w * (t * t);
    trace_w += w * p.squaredNorm();
  }
  double IsotropicMse() const { return k > 0 ? trace_w / k : 0.0; }
  double NormalTilt(double l2) const {
    return 2.0 * std::sqrt(IsotropicMse() / std::max(l2, 1e-30));
  }
  double MseAbout() const { return std::max(0.0, nqn - ns * ns / k) / k; }
  double EffectiveMse(double tilt) const {
    const double iso = IsotropicMse();
    const double expected = k > 0 ? nwn / k : 0.0;
    const double s = std::sqrt(std::max(expected, 0.0)) +
                     std::sqrt(iso) * std::min(1.0, std::max(tilt, 0.0));
    return std::min(s * s, iso);
  }
};

/// A region while it grows: its index, moments, current plane and joins since the last refit.
/// Between refits a join adds the point to the sums along the current normal only; the full
/// moments take the members joined since (members from `flushed` on) when a refit needs them,
/// in join order, so they are the same sums as those added one join at a time.
struct Growth {
  int r = 0;
  MomentSums sums;         ///< moments of the members before `flushed`
  std::size_t flushed = 0;
  NormalSums along;        ///< of every member, along fit.normal
  MomentSums merged;       ///< scratch: the full moments with a tested point
  FastFit merged_fit;      ///< scratch: the plane of `merged`
  FastFit fit;
  double since_refit = 0;
};

/// Outcome of the join test of one point.
struct JoinTest {
  bool accept = false;
  /// Growth::merged and merged_fit hold the region with the point and its plane.
  bool refitted = false;
  double merged_iso = 0;  ///< isotropic MSE of the region with the point
  /// Accepted without a refit: the region's sums along its normal with the point added.
  NormalSums along;
};

/// One PBRG pass over a cloud: the per-pixel state in the workspace and the steps of
/// Algorithm 1 (seed, grow, accept or set aside).
class PbrgPass {
 public:
  PbrgPass(const datasets::OrganizedCloud& cloud, const DetectionParams& params,
           const PointParams& point, Workspace* ws)
      : params_(params),
        point_(point),
        ws_(*ws),
        pts_(cloud.points.data()),
        n_(cloud.points.size()),
        width_(cloud.width),
        height_(cloud.height),
        spherical_(cloud.model == datasets::SensorModel::kSpherical),
        depth_model_(params.model == ThresholdModel::kDepth) {}

  /// Resets the workspace and computes each point's relative noise (sigma(z)/z)^2, -1 when invalid.
  void Prepare() {
    ws_.labels.assign(n_, kFree);
    ws_.rel2.resize(n_);
    for (std::size_t i = 0; i < n_; ++i) {
      const Eigen::Vector3f& p = pts_[i];
      if (!std::isfinite(p.z())) {
        ws_.rel2[i] = -1.0f;
        ws_.labels[i] = kInvalid;
        continue;
      }
      const double z = internal::PointDepth(p, spherical_);
      const double rel = params_.Sigma(z) / z;
      ws_.rel2[i] = static_cast<float>(rel * rel);
    }
    ws_.regions.clear();
    ws_.fits.clear();
  }

  /// Visits the points in scan order; each free one that makes a seed grows a region. Leaves
  /// each pixel's region in the labels, or kFree.
  void GrowAll() {
    for (std::size_t s = 0; s < n_; ++s) {
      if (ws_.labels[s] != kFree) continue;
      Seed seed;
      seed.s = s;
      seed.n_nb = WindowNeighbours(s, seed.nb);
      if (seed.n_nb < point_.seed_neighbours) continue;
      if (!PlanarSeed(&seed)) continue;
      Growth& g = growth_;
      StartRegion(seed, &g);
      Grow(&g);
      Flush(&g);
      CloseRegion(g.sums);
    }
    for (std::int32_t& label : ws_.labels) label = std::max(label, kFree);  // no region
  }

 private:
  /// Seed test (a): the neighbours in the 3x3 window within delta of point s that are valid and
  /// in no region; returns their count, indices in `nb`.
  int WindowNeighbours(std::size_t s, int nb[8]) const {
    const int sx = static_cast<int>(s % width_), sy = static_cast<int>(s / width_);
    const Eigen::Vector3f& ps = pts_[s];
    const double zs = internal::PointDepth(ps, spherical_);
    const float delta_s = static_cast<float>(params_.Delta(zs));
    int n_nb = 0;
    for (int oy = -1; oy <= 1; ++oy) {
      const int y = sy + oy;
      if (y < 0 || y >= height_) continue;
      for (int ox = -1; ox <= 1; ++ox) {
        const int x = sx + ox;
        if ((ox == 0 && oy == 0) || x < 0 || x >= width_) continue;
        const int i = y * width_ + x;
        if (ws_.labels[i] != kFree) continue;
        if ((pts_[i] - ps).norm() < delta_s) nb[n_nb++] = i;
      }
    }
    return n_nb;
  }

  /// Seed test (b): local planarity of the seed and its neighbours by the grid shape test
  /// (alpha, beta), or under the depth model by an MSE within the noise; fills the seed's moments
  /// and plane.
  bool PlanarSeed(Seed* seed) const {
    const Eigen::Vector3f& ps = pts_[seed->s];
    MomentSums& region = seed->region;
    region.Add(ps.x(), ps.y(), ps.z(), ws_.rel2[seed->s]);
    for (int j = 0; j < seed->n_nb; ++j) {
      const Eigen::Vector3f& q = pts_[seed->nb[j]];
      region.Add(q.x(), q.y(), q.z(), ws_.rel2[seed->nb[j]]);
    }
    const FastFit& fit = seed->fit = FitSums(region);
    if (fit.l2 <= point_.alpha * fit.l3) return false;  // linear
    bool planar = fit.l1 <= point_.beta * fit.l2;
    if (!planar && depth_model_) {
      const double noise = region.EffectiveMse(fit.normal, region.NormalTilt(fit.l2));
      planar = fit.mse <= params_.planar_sigmas * params_.planar_sigmas * noise;
    }
    return planar;
  }

  /// Labels the seed and its neighbours as the next region (Algorithm 1 line 6).
  void StartRegion(const Seed& seed, Growth* g) {
    g->r = static_cast<int>(ws_.regions.size());
    g->sums = seed.region;
    g->fit = seed.fit;
    g->since_refit = 0;
    g->along.Set(g->sums, g->fit.normal);
    ws_.members.clear();
    ws_.members.push_back(static_cast<int>(seed.s));
    for (int j = 0; j < seed.n_nb; ++j) ws_.members.push_back(seed.nb[j]);
    for (int m : ws_.members) ws_.labels[m] = g->r;
    g->flushed = ws_.members.size();
  }

  /// Adds the members joined since the last flush to the region's full moments.
  void Flush(Growth* g) const {
    const std::size_t end = ws_.members.size();
    if (g->flushed == end) return;
    // Summed in a local copy: through the pointer, every sum would be loaded and stored again
    // for each point.
    MomentSums sums = g->sums;
    const int* const members = ws_.members.data();
    for (std::size_t i = g->flushed; i < end; ++i) {
      const int m = members[i];
      const Eigen::Vector3d p = pts_[m].cast<double>();
      sums.Add(p.x(), p.y(), p.z(), ws_.rel2[m]);
    }
    g->sums = sums;
    g->flushed = end;
  }

  /// Breadth-first growth over 4-neighbours (Algorithm 1 lines 7-12), right, left, down, up.
  void Grow(Growth* g) {
    std::size_t head = 0;
    const double inv_width = 1.0 / width_;
    while (head < ws_.members.size()) {
      // The wavefront of a large region spans more rows than the caches hold: the labels, noise
      // and points around a member a few places ahead in the queue are fetched while this one
      // is tested (the same data in the same order; only the waiting is gone).
      if (head + kGrowPrefetchAhead < ws_.members.size()) {
        Prefetch(ws_.members[head + kGrowPrefetchAhead]);
      }
      const int q = ws_.members[head++];
      // The pixel's row without an integer division: (q + 0.5) / width is at least 0.5 / width
      // from an integer, far beyond the product's rounding.
      const int qy = static_cast<int>((q + 0.5) * inv_width);
      const int qx = q - qy * width_;
      if (qx + 1 < width_) Consider(q, q + 1, g);
      if (qx > 0) Consider(q, q - 1, g);
      if (qy + 1 < height_) Consider(q, q + width_, g);
      if (qy > 0) Consider(q, q - width_, g);
    }
  }

  /// Neighbour c of region point q: most are in the region already, invalid, or in R' (left
  /// PCD, Algorithm 1 line 3), told by one load here; the others (free, or in an earlier plane)
  /// are tested by TryJoin.
  void Consider(int q, int c, Growth* g) {
    const int owner = ws_.labels[c];
    if (owner == g->r || owner < kFree) return;
    TryJoin(q, c, owner, g);
  }

  /// Fetches what TryJoin reads of the 4-neighbours of pixel q (within the image's memory).
  void Prefetch(int q) const {
    const std::size_t n = n_;
    for (const std::ptrdiff_t i : {static_cast<std::ptrdiff_t>(q) - width_,
                                   static_cast<std::ptrdiff_t>(q) + width_}) {
      if (i < 0 || static_cast<std::size_t>(i) >= n) continue;
      __builtin_prefetch(&ws_.labels[i]);
      __builtin_prefetch(&ws_.rel2[i]);
      __builtin_prefetch(&pts_[i]);
    }
  }

  /// Tolerance on the distance of point c (at pc) to plane f: point noise along the
  /// normal (sigma |n.p| / z), and for a young region the normal's own uncertainty times the lever
  /// arm from the centroid (as in GBRG).
  /// `iso` is the isotropic MSE of the plane's points (MomentSums::IsotropicMse).
  double GammaFor(const FastFit& f, double iso, int c, const Eigen::Vector3d& pc) const {
    if (!depth_model_) return params_.gamma;
    const double tilt = std::min(1.0, 2.0 * std::sqrt(iso / std::max(f.l2, 1e-30)));
    const double sn = std::sqrt(ws_.rel2[c]) * std::abs(f.normal.dot(pc));
    if (tilt <= 0.02) return params_.Gamma(sn);  // a sharp normal: no lever-arm term
    const Eigen::Vector3d diff = pc - f.centroid;
    const double off = f.normal.dot(diff);
    const double lateral = std::sqrt(std::max(0.0, diff.squaredNorm() - off * off));
    return params_.Gamma(sn) + tilt * lateral;
  }

  /// Whether MSE `mse` of `merged` about plane normal `normal` (scatter eigenvalue l2) is within
  /// epsilon.
  bool MseWithinEpsilon(double mse, const MomentSums& merged, const Eigen::Vector3d& normal,
                        double l2) const {
    return mse < params_.Epsilon(merged.EffectiveMse(normal, merged.NormalTilt(l2)), merged.k);
  }

  /// The approximate join's distance test of point c (at pc) against region g's current plane.
  /// Its bound is at least its cheap part, the base gamma: within that, no roots needed.
  bool NearCurrentPlane(int c, const Eigen::Vector3d& pc, double t, const Growth& g) const {
    const double dist = std::abs(t - g.fit.d);
    return dist < params_.gamma || dist < GammaFor(g.fit, g.along.IsotropicMse(), c, pc);
  }

  /// The join test of point c (at pc, relative noise w, t = n.pc along the region's current
  /// normal) for region `g` (Algorithm 1 line 9). Between refits (refit_interval != 1), c has
  /// passed NearCurrentPlane. A refitting test leaves g's moments with c added in g->merged and
  /// their plane in g->merged_fit.
  JoinTest TestJoin(int c, const Eigen::Vector3d& pc, double t, double w, Growth* g) const {
    JoinTest test;
    const FastFit& fit = g->fit;
    if (point_.refit_interval != 1) {
      // MSE bound about the current normal, from the sums along it. The bound is at least its
      // cheap part (epsilon of the noise along the normal alone, which the tilt term only
      // raises): within that, no roots.
      NormalSums& m = test.along;
      m = g->along;
      m.AddAt(t, pc, w);
      if (MseAboutWithinEpsilon(m.k, m.nqn, m.ns, m.nwn, params_) ||
          m.MseAbout() < params_.Epsilon(m.EffectiveMse(m.NormalTilt(fit.l2)), m.k)) {
        test.accept = true;
        test.merged_iso = m.IsotropicMse();
        return test;
      }
    }
    Flush(g);
    MomentSums& merged = g->merged;
    merged.SetSum(g->sums, pc.x(), pc.y(), pc.z(), w);
    FastFit& new_fit = g->merged_fit;
    new_fit = RefitFrom(merged, fit.normal);
    test.refitted = true;
    test.merged_iso = merged.IsotropicMse();
    test.accept = MseWithinEpsilon(new_fit.mse, merged, new_fit.normal, new_fit.l2);
    if (point_.refit_interval == 1) {
      // The paper's test: distance and MSE against the plane refitted with the point.
      const double dist = std::abs(new_fit.normal.dot(pc) - new_fit.d);
      test.accept = test.accept && dist < GammaFor(new_fit, test.merged_iso, c, pc);
    }
    return test;
  }

  /// A joint point c already in an earlier plane `owner` (the paper's shared points) stays with
  /// the plane it fits best, in units of each plane's tolerance at that point. Returns true when
  /// the growing region (plane `cur`, isotropic MSE `merged_iso` with the point) takes it; its
  /// moments then leave `owner`.
  bool TakeJointPoint(int c, const Eigen::Vector3d& pc, int owner, const FastFit& cur,
                      double merged_iso) {
    const FastFit& old = ws_.fits[owner];
    const double t_new = GammaFor(cur, merged_iso, c, pc),
                 t_old = GammaFor(old, ws_.regions[owner].IsotropicMse(), c, pc);
    if (std::abs(old.normal.dot(pc) - old.d) / t_old <=
        std::abs(cur.normal.dot(pc) - cur.d) / t_new)
      return false;
    MomentSums one;
    one.Add(pc.x(), pc.y(), pc.z(), ws_.rel2[c]);
    ws_.regions[owner].Subtract(one);
    ws_.stolen.emplace_back(c, owner);
    return true;
  }

  /// Adds the point just appended to the members to the region (the test's sums with it) and
  /// updates its plane: the refitted one when the test refitted, else a refit every
  /// refit_interval joins (adaptive: every max(1, K/64)).
  void Advance(const JoinTest& test, Growth* g) const {
    g->since_refit += 1.0;
    if (test.refitted) {
      std::swap(g->sums, g->merged);
      g->flushed = ws_.members.size();
      g->fit = g->merged_fit;
      g->along.Set(g->sums, g->fit.normal);
      g->since_refit = 0;
      return;
    }
    g->along = test.along;
    const int refit_interval = point_.refit_interval;
    const double interval =
        refit_interval > 0 ? refit_interval : std::max(1.0, g->along.k / 64.0);
    if (g->since_refit >= interval) {
      Flush(g);
      g->fit = RefitFrom(g->sums, g->fit.normal);
      g->along.Set(g->sums, g->fit.normal);
      g->since_refit = 0;
    }
  }

  /// Tests neighbour c of region point q (of region `owner`, -1: none) for region `g` and adds
  /// it when it joins.
  __attribute__((noinline)) void TryJoin(int q, int c, int owner, Growth* g) {
    const Eigen::Vector3f& pq = pts_[q];
    const Eigen::Vector3f& pcf = pts_[c];
    const double zc = internal::PointDepth(pcf, spherical_);
    const double delta_c = params_.Delta(zc);
    if ((pcf - pq).squaredNorm() >= delta_c * delta_c) return;  // dis(GR, p_c) < delta
    const Eigen::Vector3d pc = pcf.cast<double>();
    const double t = g->fit.normal.dot(pc);
    // Between refits the distance to the current plane turns most points away before their
    // merged moments are formed.
    if (point_.refit_interval != 1 && !NearCurrentPlane(c, pc, t, *g)) return;
    const double w = ws_.rel2[c];
    const JoinTest test = TestJoin(c, pc, t, w, g);
    if (!test.accept) return;
    if (owner >= 0 &&
        !TakeJointPoint(c, pc, owner, test.refitted ? g->merged_fit : g->fit, test.merged_iso))
      return;
    ws_.labels[c] = g->r;
    ws_.members.push_back(c);
    Advance(test, g);
  }

  /// Keeps a grown region of at least theta points as a plane (R); a smaller one goes to R' (its
  /// points leave PCD: no seed, no growth) and the joint points it took go back to their plane.
  void CloseRegion(const MomentSums& region) {
    if (static_cast<int>(ws_.members.size()) >= params_.theta) {
      ws_.regions.push_back(region);
      ws_.fits.push_back(FitSums(region));
    } else {
      for (int m : ws_.members) ws_.labels[m] = kSetAside;
      for (const auto& [point, owner] : ws_.stolen) {
        const Eigen::Vector3f& q = pts_[point];
        ws_.regions[owner].Add(q.x(), q.y(), q.z(), ws_.rel2[point]);
        ws_.labels[point] = owner;
      }
    }
    ws_.stolen.clear();
  }

  const DetectionParams& params_;
  const PointParams& point_;
  Workspace& ws_;
  const Eigen::Vector3f* pts_;
  std::size_t n_;
  int width_, height_;
  bool spherical_;
  bool depth_model_;
  Growth growth_;  ///< the region growing
};

}  // namespace

std::vector<std::string> PointParams::Validate() const {
  std::vector<std::string> problems;
  if (seed_neighbours < 2 || seed_neighbours > 8)
    problems.push_back("seed_neighbours must be in [2, 8]");
  if (!(alpha > 0 && alpha < 1)) problems.push_back("alpha must be in (0, 1)");
  if (!(beta > 0 && beta < 1)) problems.push_back("beta must be in (0, 1)");
  if (refit_interval < 0) problems.push_back("refit_interval must be >= 0 (0 = adaptive)");
  return problems;
}

PointRegionGrowing::PointRegionGrowing(const DetectionParams& params, const PointParams& point,
                                       std::string name)
    : params_(params), point_(point), name_(std::move(name)) {
  auto problems = params_.Validate();
  auto more = point_.Validate();
  problems.insert(problems.end(), more.begin(), more.end());
  PLANESLAM_CHECK(problems.empty(), "invalid PBRG parameters: " << problems.front());
}

Segmentation PointRegionGrowing::Detect(const datasets::OrganizedCloud& cloud) const {
  Segmentation out;
  const int width = cloud.width, height = cloud.height;
  PLANESLAM_CHECK(cloud.points.size() == static_cast<std::size_t>(width) * height,
                  "organized cloud size mismatch");
  out.width = width;
  out.height = height;
  if (cloud.points.empty()) return out;
  Workspace& ws = internal::ThreadScratch<Workspace>();
  PbrgPass pass(cloud, params_, point_, &ws);

  const auto t0 = Clock::now();
  pass.Prepare();
  const auto t1 = Clock::now();
  pass.GrowAll();
  const auto t2 = Clock::now();
  internal::FinalizeLabelImage(cloud, ws.labels, ws.regions, params_, out);
  const auto t3 = Clock::now();
  out.timings_ms = {{"prepare", Ms(t0, t1)}, {"grow", Ms(t1, t2)}, {"finalize", Ms(t2, t3)}};
  return out;
}

}  // namespace planeslam::detection

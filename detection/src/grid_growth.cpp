// GBRG stage 2: region growing over the grid image (Xiao et al. 2011, Algorithm 2).
#include <algorithm>
#include <cmath>

#include "grid_pipeline.hpp"

namespace planeslam::detection::gbrg {
namespace {

/// Growth mark of a grid that can no longer join a region (see GrowthWork::mark).
constexpr std::int32_t kTaken = -2;

/// How many queue places ahead the growth prefetches grid data.
constexpr std::size_t kPrefetchAhead = 6;

/// A growing region whose second-smallest spread l2 / K is within this many times its ray noise
/// has no resolved normal yet (grid-level pipeline): on a far wall, where the noise exceeds a
/// grid's width, a strip of grids fits a plane across the strip, so such a region joins grids by
/// the MSE test alone.
constexpr double kUnresolvedSpread = 2.0;

/// The growth's buffers, reused across frames.
struct GrowthWork {
  /// Growth state of each grid, one load per look: kTaken (not planar, or in R or R'), else the
  /// last region that queued it (-1: none yet).
  std::vector<std::int32_t> mark;
  std::vector<int> queue;
  std::vector<int> members;                 ///< the grids of the region growing
  std::vector<int> left_out;                ///< the grids of R' after the first growth
  std::vector<std::uint8_t> region_fitted;  ///< whether fits holds a plane's fit yet
  std::vector<FastFit> fits;                ///< the planes as grown (second growth)
};

/// The region being grown: its moments, plane, and the uncertainty of its normal.
struct GrowingRegion {
  MomentSums sums;
  FastFit fit;
  /// The normal's own uncertainty (depth model), kept with the fit: the tilt [rad] and its
  /// cosine and sine, which widen every grid's angle tolerance.
  double tilt = 0.0, cos_tilt = 1.0, sin_tilt = 0.0;
  /// Whether the normal is resolved (grid-level pipeline): while the second-smallest spread
  /// l2 / K is within kUnresolvedSpread times the ray noise, the depth noise and the region's
  /// narrow side are not told apart, and the fitted normal may lie in the surface (a strip of
  /// grids on a far wall fits the plane across the strip, not the wall).
  bool normal_resolved = true;
  int since_refit = 0;  ///< joins since the plane was last refitted
};

/// Grows regions from seeds, one at a time (Algorithm 2 lines 5-15).
class RegionGrower {
 public:
  RegionGrower(const GridImage& image, const CellMoments& cells, Regions& regions, GrowthWork& work)
      : image_(image),
        params_(image.params),
        grid_(image.grid),
        cells_(cells),
        regions_(regions),
        work_(work),
        depth_model_(image.depth_model),
        adaptive_refit_(grid_.refit_interval != 1),
        theta_grids_(static_cast<std::size_t>((params_.theta + image.k * image.k - 1) /
                                              (image.k * image.k))) {
    // A grid is queued at most once for each neighbour that joins the region (then taken, or
    // rejected and free to be queued again): 4 per grid bounds a region's queue.
    work_.queue.resize(4 * static_cast<std::size_t>(image.num_cells) + 4);
  }

  /// The region grown from `seed`: a plane when it has ceil(theta / k^2) grids or more; else its
  /// grids leave G (R'), kept in work.left_out in the first growth of the grid-level pipeline.
  void GrowFrom(int seed) {
    r_ = static_cast<int>(regions_.sums.size());
    GrowingRegion region;
    region.sums = cells_.sums[seed];
    region.fit = FitSums(region.sums);
    if (depth_model_) UpdateTilt(region, region.sums.NormalTilt(region.fit.l2));
    work_.members.clear();
    work_.members.push_back(seed);
    regions_.cell_region[seed] = r_;
    work_.mark[seed] = kTaken;
    // The queue in a buffer with room for every push, so a push needs no check.
    queue_ = work_.queue.data();
    head_ = tail_ = 0;
    PushNeighbours(seed);
    while (head_ < tail_) {
      const int g = queue_[head_++];
      if (work_.mark[g] == kTaken) continue;
      work_.mark[g] = -1;  // may be queued again by a later neighbour if rejected now
      // The wavefront of a large region spans more grids than the cache holds: fetch the data of
      // the grids a few places ahead in the queue while this one is tested. A grid's sums (128
      // bytes) lie across three cache lines unless the array happens to start on a line: all
      // three are fetched.
      if (head_ + kPrefetchAhead < tail_) {
        const int ahead = queue_[head_ + kPrefetchAhead];
        __builtin_prefetch(&cells_.info[ahead]);
        __builtin_prefetch(&cells_.sums[ahead]);
        __builtin_prefetch(reinterpret_cast<const char*>(&cells_.sums[ahead]) + 64);
        __builtin_prefetch(reinterpret_cast<const char*>(&cells_.sums[ahead]) + sizeof(MomentSums) -
                           1);
      }
      if (!Joins(region, g)) continue;
      regions_.cell_region[g] = r_;
      work_.mark[g] = kTaken;
      work_.members.push_back(g);
      PushNeighbours(g);
    }
    if (work_.members.size() >= theta_grids_) {
      regions_.sums.push_back(region.sums);
    } else {
      // R' (Algorithm 2 line 15): these grids leave G, as in the paper: they neither seed nor join
      // later regions (re-growing later regions into them makes the growth quadratic on
      // cluttered scans). Boundary refinement may still give their pixels to a plane, and in the
      // grid-level pipeline they grow once more after all seeds (GrowLeftOut).
      for (int c : work_.members) regions_.cell_region[c] = -1;
      if (grid_.grid_level && !second_growth_) {
        work_.left_out.insert(work_.left_out.end(), work_.members.begin(), work_.members.end());
      }
    }
  }

  void StartSecondGrowth() { second_growth_ = true; }

 private:
  void UpdateTilt(GrowingRegion& region, double raw_tilt) const {
    region.normal_resolved = !(region.fit.l2 < (grid_.grid_level ? kUnresolvedSpread : 0.0) *
                                                   region.sums.IsotropicMse() * region.sums.k);
    region.tilt = std::min(1.0, raw_tilt);
    if (region.tilt > 0.02) {  // below, the tests ignore the tilt (see there)
      SinCosFirstQuadrant(region.tilt, region.sin_tilt, region.cos_tilt);  // 0.02 < tilt <= 1
    }
  }

  /// Right, left, down, up, without a branch per neighbour (whether one is queued is data, not a
  /// pattern): each is written to the queue's end, which advances only if it is queued; one
  /// outside the image is c itself, which is taken.
  void PushNeighbours(int c) {
    const int cells_x = image_.cells_x;
    const auto [cx, cy] = image_.Xy(c);
    const int neighbours[4] = {cx + 1 < cells_x ? c + 1 : c, cx > 0 ? c - 1 : c,
                               cy + 1 < image_.cells_y ? c + cells_x : c, cy > 0 ? c - cells_x : c};
    std::int32_t* const marks = work_.mark.data();
    for (const int nb : neighbours) {
      // Not planar, in R, R' or this region; or queued already.
      const std::int32_t mark = marks[nb];
      const bool queued = (mark != kTaken) & (mark != r_);
      queue_[tail_] = nb;
      tail_ += queued;
      marks[nb] = queued ? r_ : mark;
    }
  }

  /// Algorithm 2 line 8: whether grid g joins the region (then added to it): angle,
  /// coplanarity, then the merged MSE (the only one needing a fit).
  bool Joins(GrowingRegion& region, int g) {
    const CellInfo& ci = cells_.info[g];
    const MomentSums& gs = cells_.sums[g];
    const FastFit& fit = region.fit;
    const double tilt = region.tilt;
    const Eigen::Vector3d diff = fit.centroid - ci.m.cast<double>();
    const Eigen::Vector3d grid_normal = ci.n.cast<double>();
    const double cos_tol = ci.cos_tol, sin_tol = ci.sin_tol;
    const double off = std::abs(fit.normal.dot(diff));
    if (depth_model_ && !region.normal_resolved) {
      // No angle or coplanarity test against an unresolved normal: the MSE test below (of the
      // merged fit, whatever its normal) decides alone, and the region grows across its narrow
      // side until the spread there exceeds the noise and the normal is the surface's.
    } else if (depth_model_) {
      // A young region's own normal is uncertain (tilt, 2 sigma): widen the angle test by it
      // and let the coplanarity test allow tilt x lateral distance, so that a seed with a
      // noisy normal corrects itself by growing instead of growing a strip along its error.
      const double dot = std::abs(fit.normal.dot(grid_normal));
      if (tilt > 0.02) {
        // cos(tolerance + tilt); the sum stays below 3 pi / 2, so cos > 0 iff it is < pi / 2.
        const double cos_ang = cos_tol * region.cos_tilt - sin_tol * region.sin_tilt;
        if (cos_tol >= 0 && cos_ang > 0 && dot <= cos_ang) return false;
      } else if (dot <= cos_tol)
        return false;
      // The bound below is at least the base gamma, which admits most grids of a plane: only
      // the others pay for its square roots.
      if (off >= params_.gamma) {
        const double lateral = std::sqrt(std::max(0.0, diff.squaredNorm() - off * off));
        // Noise of the grid's centre along the region normal: sigma_n / sqrt(K_g).
        const double gamma =
            params_.Gamma(std::sqrt(gs.EffectiveMse(fit.normal, tilt) / gs.k)) + tilt * lateral;
        if (off >= gamma) return false;
      }
    } else {
      if (std::abs(fit.normal.dot(grid_normal)) <= cos_tol) return false;
      if (off >= params_.gamma) return false;
    }
    return MseTestJoins(region, gs);
  }

  /// The merged MSE test (and the join), with the cheap bound first: the noise along the normal
  /// alone is a lower bound of the effective noise (its tilt term only adds), and the MSE about
  /// the current normal an upper bound of the merged fit's, so either passing the test passes
  /// the exact one.
  bool MseTestJoins(GrowingRegion& region, const MomentSums& gs) {
    MomentSums merged = region.sums;
    merged.Merge(gs);
    if (adaptive_refit_ && MseAboutWithinEpsilon(merged, region.fit.normal, params_)) {
      region.sums = merged;
      region.since_refit += 1;
      const int interval = grid_.refit_interval > 0
                               ? grid_.refit_interval
                               : std::max(1, static_cast<int>(work_.members.size()) / 64);
      if (region.since_refit >= interval) {
        region.fit = RefitFrom(region.sums, region.fit.normal);
        if (depth_model_) UpdateTilt(region, region.sums.NormalTilt(region.fit.l2));
        region.since_refit = 0;
      }
      return true;
    }
    const FastFit merged_fit = RefitFrom(merged, region.fit.normal);
    const double merged_tilt = merged.NormalTilt(merged_fit.l2);
    if (merged_fit.mse >= params_.Epsilon(merged.ExpectedMse(merged_fit.normal), merged.k)) {
      const double expected = merged.EffectiveMse(merged_fit.normal, merged_tilt);
      if (merged_fit.mse >= params_.Epsilon(expected, merged.k)) return false;
    }
    region.sums = merged;
    region.fit = merged_fit;  // eq. (5): plane parameters updated on the join
    if (depth_model_) UpdateTilt(region, merged_tilt);
    region.since_refit = 0;
    return true;
  }

  const GridImage& image_;
  const DetectionParams& params_;
  const GridParams& grid_;
  const CellMoments& cells_;
  Regions& regions_;
  GrowthWork& work_;
  const bool depth_model_;
  const bool adaptive_refit_;  // else the paper's refit per join
  const std::size_t theta_grids_;
  bool second_growth_ = false;
  int r_ = 0;  // the index of the region growing
  int* queue_ = nullptr;
  std::size_t head_ = 0, tail_ = 0;
};

/// Seeds in key order. Most grids join one of the first regions, so instead of sorting every key
/// up front the keys are taken in chunks: the smallest chunk is selected and sorted, its seeds
/// are grown, and the keys of grids used meanwhile are dropped before the next chunk. Keys are
/// unique (grid index in the low bits), so the order is exactly that of a full sort.
void GrowFromSeeds(std::vector<std::uint64_t>& seeds, const std::vector<std::int32_t>& mark,
                   RegionGrower& grower) {
  std::size_t next = 0;
  while (next < seeds.size()) {
    // The keys of grids used meanwhile dropped, in order, without a branch per key (whether a
    // grid is taken is data, not a pattern).
    std::size_t kept = next;
    for (std::size_t i = next; i < seeds.size(); ++i) {
      const std::uint64_t key = seeds[i];
      seeds[kept] = key;
      kept += mark[key & 0xffffffffu] != kTaken;
    }
    seeds.resize(kept);
    if (next >= seeds.size()) break;
    // The chunk: the keys below a threshold taken from a sample of the keys left, moved to the
    // front in one pass (std::partition; nth_element takes two to three). A sample key is
    // itself a key left, so at least the smallest sample key is below the threshold.
    const std::size_t remaining = seeds.size() - next;
    const std::size_t chunk = std::max<std::size_t>(256, remaining / 32);
    const auto first = seeds.begin() + static_cast<std::ptrdiff_t>(next);
    auto last = seeds.end();
    if (remaining > chunk) {
      constexpr std::size_t kSample = 64;
      std::uint64_t sample[kSample];
      for (std::size_t s = 0; s < kSample; ++s) sample[s] = first[s * remaining / kSample];
      std::sort(sample, sample + kSample);
      const std::uint64_t threshold =
          sample[std::clamp<std::size_t>(kSample * chunk / remaining, 1, kSample - 1)];
      last = std::partition(first, seeds.end(),
                            [threshold](std::uint64_t key) { return key < threshold; });
    }
    std::sort(first, last);
    const std::size_t end = static_cast<std::size_t>(last - seeds.begin());
    for (; next < end; ++next) {
      const int seed = static_cast<int>(seeds[next] & 0xffffffffu);
      if (mark[seed] != kTaken) grower.GrowFrom(seed);  // else already in R or R'
    }
  }
}

/// The second growth of the grid-level pipeline: the grids of R' that fit none of the planes
/// around them (3 x 3 grids; the planes as grown, fixed during the pass) seed and grow again, in
/// seed order; every other grid is taken now, so they grow among themselves only. The rest stay
/// out (the grid-level refinement may give them to the plane they fit). The planes are fitted
/// as needed.
void GrowLeftOut(const GridImage& image, CellMoments& cells, Regions& regions, GrowthWork& work,
                 RegionGrower& grower) {
  grower.StartSecondGrowth();
  work.fits.resize(regions.sums.size());
  work.region_fitted.assign(regions.sums.size(), 0);
  std::vector<std::uint64_t>& seeds = cells.seeds;
  seeds.clear();
  for (const int c : work.left_out) {
    const auto [cx, cy] = image.Xy(c);
    bool fits_a_plane = false;
    for (int i = 0; i < 9 && !fits_a_plane; ++i) {
      const int r = image.RegionAt(regions.cell_region, cx + i % 3 - 1, cy + i / 3 - 1);
      if (r < 0) continue;
      if (!work.region_fitted[r]) {
        work.fits[r] = FitSums(regions.sums[r]);
        work.region_fitted[r] = 1;
      }
      fits_a_plane = GridFitRatio(image, cells.sums[c], work.fits[r]) < 1.0;
    }
    if (fits_a_plane) continue;
    work.mark[c] = -1;
    seeds.push_back(cells.seed_keys[c]);
  }
  std::sort(seeds.begin(), seeds.end());
  for (const std::uint64_t key : seeds) {
    const int seed = static_cast<int>(key & 0xffffffffu);
    if (work.mark[seed] != kTaken) grower.GrowFrom(seed);
  }
}

}  // namespace

// Seeds in order of grid MSE, breadth-first over 4-neighbours.
void GrowRegions(const GridImage& image, CellMoments& cells, Regions& regions) {
  GrowthWork& work = internal::ThreadScratch<GrowthWork>();
  const int num_cells = image.num_cells;
  regions.cell_region.assign(num_cells, -1);
  work.mark.resize(num_cells);
  for (int c = 0; c < num_cells; ++c) {
    work.mark[c] = cells.classes[c] == CellClass::kPlanar ? -1 : kTaken;
  }
  regions.sums.clear();
  work.left_out.clear();
  RegionGrower grower(image, cells, regions, work);
  GrowFromSeeds(cells.seeds, work.mark, grower);
  if (image.grid.grid_level && !work.left_out.empty()) {
    GrowLeftOut(image, cells, regions, work, grower);
  }
}

}  // namespace planeslam::detection::gbrg

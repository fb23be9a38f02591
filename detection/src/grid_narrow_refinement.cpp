// GBRG stage 3c, the grid-level pipeline's fits: interior and apart fits of the planes of whole
// grids, and the pixel refinement and block fit of planes too narrow for either.
#include <algorithm>
#include <tuple>

#include "grid_pipeline.hpp"

namespace planeslam::detection::gbrg {
namespace {

/// The smallest narrow plane [points] refined pixel by pixel; smaller ones are mostly slivers of a
/// neighbouring plane, which keep whole grids.
constexpr double kNarrowRefinePoints = 2000.0;

/// The narrow planes' buffers, reused across frames.
struct NarrowWork {
  std::vector<std::uint8_t> narrow;    ///< per plane: too narrow for the interior fit
  std::vector<MomentSums> apart_sums;  ///< such a plane without its grids next to another plane
  std::vector<RaySums> apart_rays;
  std::vector<std::uint8_t> too_narrow;     ///< planes too narrow for the apart fit as well
  std::vector<std::uint8_t> refine_pixels;  ///< those of them refined pixel by pixel
  std::vector<std::pair<int, int>> narrow_plane_grids;  ///< (such a plane, one of its grids)
  std::vector<int> narrow_grids;                        ///< the grids of one such plane
  std::vector<int> around;                              ///< the grids around them
  std::vector<int> visit;       ///< per grid: the last such plane it was found around (-1: none)
  std::vector<int> candidates;  ///< the plane and the planes next to it
  std::vector<int> candidate_grid;      ///< a grid of each (for its plane id)
  std::vector<float> candidate_planes;  ///< n, d of each (PixelChoice::BestPlane)
  /// Each pixel's choice: (pixel, its grid, candidate: 0 the plane itself, -1 none; for a pixel
  /// of a grid around that stays, the grid's own plane's candidate, or -2 when that is none).
  std::vector<std::tuple<std::size_t, int, int>> choices;
  /// The moves: (pixel, its grid, candidate it goes to: 0 the plane itself, -1 none).
  std::vector<std::tuple<std::size_t, int, int>> moves;
  std::vector<internal::RayPlane> candidate_ray_planes;
  std::vector<float> block_ratio;  ///< per candidate
};

/// A plane too narrow for its grids apart from the other planes as well (a column of grids or
/// two, each next to another plane) holds another surface's pixels in most of its grids: fitted
/// to all of them it is tilted towards that surface, and labelled with grids that hold as much
/// of the other surface as of it (a wall seen edge-on, as narrow as a grid or two). Its grids and
/// the grids around them get the pixel-level refinement of the other methods: a pixel of its
/// grids goes to whichever of it and the planes next to its grids fits the pixel best within the
/// pixel's tolerance, else to none; a pixel of a grid around goes to it when it fits the pixel
/// within tolerance and better than the grid's own plane does. Its plane is then fitted to its
/// pixels; labels and sums follow. (A pixel it gives away to a plane that is too narrow as well
/// goes to none.) Only planes of kNarrowRefinePoints or more.
class NarrowPlaneRefiner {
 public:
  NarrowPlaneRefiner(const GridImage& image, const CellMoments& cells, Regions& regions,
                     GridFits& fits, NarrowWork& work)
      : image_(image),
        params_(image.params),
        cells_(cells),
        regions_(regions),
        fits_(fits),
        work_(work),
        choice_(image) {}

  void Refine(int r, const std::vector<int>& grids) {
    CollectCandidates(r, grids);
    ChooseFirst(grids);
    if (params_.ray_fit) ChooseAlongRays(grids);
    Apply(r, grids);
  }

 private:
  /// Calls visit_pixel(i, p) for each valid pixel i (point p) of grid c.
  template <typename Visit>
  void ForEachPixel(int c, const Visit& visit_pixel) const {
    const int k = image_.k, width = image_.width;
    const auto [cx, cy] = image_.Xy(c);
    const int x0 = cx * k, y0 = cy * k;
    const int x1 = std::min(width, x0 + k), y1 = std::min(image_.height, y0 + k);
    for (int y = y0; y < y1; ++y) {
      for (int x = x0; x < x1; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * width + x;
        const Eigen::Vector3f& pf = image_.pts[i];
        if (std::isfinite(pf.z())) visit_pixel(i, pf);
      }
    }
  }

  void AddCandidate(int region, int grid, const MomentSums& m) {
    work_.candidates.push_back(region);
    work_.candidate_grid.push_back(grid);
    AppendPlaneNd(m, work_.candidate_planes);
  }

  /// Its plane and the planes next to its grids, as BestPlane's candidates; and, from the same
  /// walk over the 3 x 3 neighbourhoods of its grids, the grids around its grids (each once; not
  /// those of a plane too narrow as well).
  void CollectCandidates(int r, const std::vector<int>& grids) {
    std::vector<int>& candidates = work_.candidates;
    candidates.clear();
    work_.candidate_grid.clear();
    work_.candidate_planes.clear();
    AddCandidate(r, grids.front(), regions_.sums[r]);
    work_.around.clear();
    for (const int c : grids) {
      const auto [cx, cy] = image_.Xy(c);
      for (int i = 0; i < 9; ++i) {
        const int ox = cx + i % 3 - 1, oy = cy + i / 3 - 1;
        if (ox < 0 || oy < 0 || ox >= image_.cells_x || oy >= image_.cells_y) continue;
        const int n = oy * image_.cells_x + ox;
        const int o = regions_.cell_region[n];
        if (o == r) continue;
        if (o >= 0 && std::find(candidates.begin(), candidates.end(), o) == candidates.end()) {
          const MomentSums& m = fits_.sums[o].k >= 3 ? fits_.sums[o] : regions_.sums[o];
          if (m.k >= 3) AddCandidate(o, n, m);
        }
        if ((o >= 0 && work_.too_narrow[o]) || cells_.counts[n] == 0 || work_.visit[n] == r)
          continue;
        work_.visit[n] = r;
        work_.around.push_back(n);
      }
    }
  }

  /// Its grids' pixels: to the best candidate (0: itself), else to none. The pixels of the grids
  /// around its grids: to it when it is the better of it and the grid's own plane, within
  /// tolerance.
  void ChooseFirst(const std::vector<int>& grids) {
    const std::vector<int>& candidates = work_.candidates;
    const std::vector<float>& planes = work_.candidate_planes;
    auto& choices = work_.choices;
    choices.clear();
    const int num_candidates = static_cast<int>(candidates.size());
    for (const int c : grids) {
      ForEachPixel(c, [&](std::size_t i, const Eigen::Vector3f& pf) {
        const float z = internal::PointDepth(pf, image_.spherical);
        choices.push_back(
            {i, c, choice_.BestPlane(pf, choice_.RelativeNoise(z), planes.data(), num_candidates)});
      });
    }
    num_own_grid_pixels_ = choices.size();
    for (const int n : work_.around) {
      const int o = regions_.cell_region[n];
      const int j =
          static_cast<int>(std::find(candidates.begin(), candidates.end(), o) - candidates.begin());
      float pair[8];  // itself, then the grid's own plane if it is a candidate
      std::copy(planes.begin(), planes.begin() + 4, pair);
      const int num_pair = j < num_candidates ? 2 : 1;
      if (num_pair == 2) std::copy(planes.begin() + 4 * j, planes.begin() + 4 * j + 4, pair + 4);
      const int stays = num_pair == 2 ? j : o < 0 ? -1 : -2;
      ForEachPixel(n, [&](std::size_t i, const Eigen::Vector3f& pf) {
        const float z = internal::PointDepth(pf, image_.spherical);
        const bool joins = choice_.BestPlane(pf, choice_.RelativeNoise(z), pair, num_pair) == 0;
        choices.push_back({i, n, joins ? 0 : stays});
      });
    }
  }

  void AddToFirst(const Eigen::Vector3f& pf) {
    first_.AddPosition(pf.x(), pf.y(), pf.z());
    const float z = internal::PointDepth(pf, image_.spherical);
    if (z > 0.0f) first_rays_.Add(pf, z, params_.RayFitWeight(z));
  }

  /// Its own plane along the rays, fitted to the blocks of 2 x 2 pixels of its grids that fit it
  /// better than any other candidate, within tolerance (summed squared distances in units of each
  /// pixel's tolerance), rather than to the pixels chosen first: its eigen fit is tilted towards
  /// the neighbour its whole grids hold too, the pixels of the neighbour's strip along the crease
  /// fit it, and a fit of them keeps the tilt. A block averages the noise of four pixels, so it
  /// tells the two surfaces apart where a pixel cannot. With no such block, the pixels chosen
  /// first. (Only the choice along the rays uses this fit; the plane's final fit is of its
  /// pixels.)
  void FitToBlocks(const std::vector<int>& grids) {
    constexpr int kBlock = 2;
    const int k = image_.k, width = image_.width;
    const int num_candidates = static_cast<int>(work_.candidates.size());
    const std::vector<float>& planes = work_.candidate_planes;
    std::vector<float>& block_ratio = work_.block_ratio;
    block_ratio.resize(num_candidates);
    first_ = MomentSums();
    first_rays_ = RaySums();
    for (const int c : grids) {
      const auto [cx, cy] = image_.Xy(c);
      const int gx0 = cx * k, gy0 = cy * k;
      const int gx1 = std::min(width, gx0 + k), gy1 = std::min(image_.height, gy0 + k);
      for (int by = gy0; by < gy1; by += kBlock) {
        for (int bx = gx0; bx < gx1; bx += kBlock) {
          const int bx1 = std::min(gx1, bx + kBlock), by1 = std::min(gy1, by + kBlock);
          auto for_each_block_point = [&](const auto& visit) {
            for (int y = by; y < by1; ++y) {
              for (int x = bx; x < bx1; ++x) {
                const Eigen::Vector3f& pf = image_.pts[static_cast<std::size_t>(y) * width + x];
                if (std::isfinite(pf.z())) visit(pf);
              }
            }
          };
          std::fill(block_ratio.begin(), block_ratio.end(), 0.0f);
          int count = 0;
          for_each_block_point([&](const Eigen::Vector3f& pf) {
            ++count;
            const float rel = choice_.RelativeNoise(internal::PointDepth(pf, image_.spherical));
            for (int j = 0; j < num_candidates; ++j) {
              float dist, tol;
              choice_.DistanceAndTolerance(pf, rel, planes.data() + 4 * j, dist, tol);
              block_ratio[j] += dist * dist / std::max(tol * tol, 1e-18f);
            }
          });
          if (count == 0 || !(block_ratio[0] < count)) continue;
          const auto best = std::min_element(block_ratio.begin(), block_ratio.end());
          if (best != block_ratio.begin()) continue;  // another candidate fits it better
          for_each_block_point([&](const Eigen::Vector3f& pf) { AddToFirst(pf); });
        }
      }
    }
    if (first_.k < 3) {
      for (const auto& [i, c, to] : work_.choices) {
        if (to == 0) AddToFirst(image_.pts[i]);
      }
    }
  }

  /// The candidates are eigen fits, and its own, of grids that hold other surfaces too, is
  /// tilted (on a surface seen at a grazing angle, by the depth noise as well: see ray_fit), so
  /// the pixels chosen against it are too. With the ray fit the choice is made a second time
  /// against the planes along the rays (its own fitted to blocks, the others' of their fit
  /// subsets), as the final crease competition of the pixel-level methods makes it: a pixel
  /// moves to a candidate whose surface its ray sees (VisibleHere), and a pixel of no plane joins
  /// the candidate that passes nearest it along the ray, within the gate.
  void ChooseAlongRays(const std::vector<int>& grids) {
    FitToBlocks(grids);
    const std::vector<int>& candidates = work_.candidates;
    auto& ray_planes = work_.candidate_ray_planes;
    ray_planes.assign(candidates.size(), internal::RayPlane());
    ray_planes[0] = internal::SolveRegion(first_rays_, first_);
    for (std::size_t j = 1; j < candidates.size(); ++j) {
      const int o = candidates[j];
      ray_planes[j] = fits_.sums[o].k >= 3
                          ? internal::SolveRegion(fits_.rays[o], fits_.sums[o])
                          : internal::SolveRegion(regions_.rays[o], regions_.sums[o]);
    }
    if (!ray_planes[0].ok) return;
    const int num_candidates = static_cast<int>(candidates.size());
    auto& choices = work_.choices;
    for (std::size_t e = 0; e < choices.size(); ++e) {
      auto& [i, c, to] = choices[e];
      if (to == -2) continue;  // a pixel of a plane that is no candidate
      const Eigen::Vector3f& pf = image_.pts[i];
      const float s = internal::PointDepth(pf, image_.spherical);
      if (!(s > 0.0f)) continue;
      // A pixel of a grid around only to this plane.
      const int num_targets = e < num_own_grid_pixels_ ? num_candidates : 1;
      if (to < 0) {
        // Of no plane: to the nearest candidate along the ray within the gate.
        double best_offset = internal::kCreaseGateSigmas * params_.Sigma(s);
        for (int j = 0; j < num_targets; ++j) {
          if (!ray_planes[j].ok) continue;
          const double offset = internal::RayOffset(pf, s, ray_planes[j]);
          if (offset < best_offset) {
            best_offset = offset;
            to = j;
          }
        }
        continue;
      }
      if (!ray_planes[to].ok) continue;
      // Of a plane: to another whose surface its ray sees.
      for (int j = 0; j < num_targets; ++j) {
        if (j == to || !ray_planes[j].ok) continue;
        if (internal::VisibleHere(pf, s, ray_planes[to], ray_planes[j], params_)) {
          to = j;
          break;
        }
      }
    }
  }

  /// Applies the choices: its sums become those of its pixels; the others' gain and lose what
  /// moved. With nothing of its own, it stays as it was.
  void Apply(int r, const std::vector<int>& grids) {
    auto& moves = work_.moves;
    moves.clear();
    MomentSums own;
    const auto& choices = work_.choices;
    for (std::size_t e = 0; e < choices.size(); ++e) {
      const auto& [i, c, to] = choices[e];
      const bool own_grid = e < num_own_grid_pixels_;
      if (!own_grid && to != 0) continue;  // a pixel around that stays where it was
      const Eigen::Vector3f& pf = image_.pts[i];
      if (to == 0) own.Add(pf.x(), pf.y(), pf.z(), cells_.noise_weight[c]);
      if (!own_grid || to != 0) moves.emplace_back(i, c, to);
    }
    if (own.k < 3) return;
    RaySums own_rays;
    for (const int c : grids) {
      // Its grids' rays, less those of the pixels that leave (added below with weight -w).
      if (params_.ray_fit) own_rays.Add(cells_.grid_rays[c]);
    }
    for (const auto& [i, c, to] : moves) {
      const Eigen::Vector3f& pf = image_.pts[i];
      const float z = internal::PointDepth(pf, image_.spherical);
      const int from = regions_.cell_region[c];
      MomentSums pixel;
      pixel.Add(pf.x(), pf.y(), pf.z(), cells_.noise_weight[c]);
      if (to == 0) {  // from a grid around into this plane
        if (from >= 0) regions_.sums[from].Subtract(pixel);
        if (params_.ray_fit && z > 0.0f) own_rays.Add(pf, z, params_.RayFitWeight(z));
        fits_.pixel_overrides.emplace_back(i, grids.front());
        continue;
      }
      // Out of this plane's grids: to another plane, or to none.
      if (params_.ray_fit && z > 0.0f) own_rays.Add(pf, z, -params_.RayFitWeight(z));
      const bool to_other = to > 0 && !work_.too_narrow[work_.candidates[to]];
      if (to_other) regions_.sums[work_.candidates[to]].Merge(pixel);
      fits_.pixel_overrides.emplace_back(i, to_other ? work_.candidate_grid[to] : -1);
    }
    regions_.sums[r] = own;
    fits_.sums[r] = own;
    if (params_.ray_fit) fits_.rays[r] = own_rays;
  }

  const GridImage& image_;
  const DetectionParams& params_;
  const CellMoments& cells_;
  Regions& regions_;
  GridFits& fits_;
  NarrowWork& work_;
  const PixelChoice choice_;
  std::size_t num_own_grid_pixels_ = 0;  // the choices of its own grids' pixels come first
  MomentSums first_;                     // what its plane along the rays is fitted to
  RaySums first_rays_;
};

/// Each plane's interior grids (all 8 neighbours in the same plane before merging): every grid
/// of a plane that is not an edge grid. Their sums and ray sums have left the caches since the
/// moments pass: fetched a few edge grids ahead.
void FitInteriorGrids(const GridImage& image, const CellMoments& cells, const EdgeGrids& edges,
                      const Regions& regions, GridFits& fits) {
  const bool ray_fit = image.params.ray_fit;
  fits.sums = regions.sums;
  fits.rays = regions.rays;
  const std::size_t num_edge = edges.grids.size();
  for (std::size_t e = 0; e < num_edge; ++e) {
    if (e + kRefinePrefetchAhead < num_edge) {
      const int ahead = edges.grids[e + kRefinePrefetchAhead];
      const char* sums = reinterpret_cast<const char*>(&cells.sums[ahead]);
      __builtin_prefetch(sums);
      __builtin_prefetch(sums + 64);
      __builtin_prefetch(sums + sizeof(MomentSums) - 1);
      if (ray_fit) {
        const char* rays = reinterpret_cast<const char*>(&cells.grid_rays[ahead]);
        __builtin_prefetch(rays);
        __builtin_prefetch(rays + sizeof(RaySums) - 1);
      }
    }
    const int c = edges.grids[e];
    const int r = regions.cell_region[c];
    if (r < 0) continue;
    fits.sums[r].Subtract(cells.sums[c]);
    if (ray_fit) fits.rays[r].Subtract(cells.grid_rays[c]);
  }
}

/// The fits of the narrow planes (too narrow for their interior grids): their grids apart from
/// the grids next to another plane, or, too narrow for that as well, all their grids (then
/// marked too_narrow, and from kNarrowRefinePoints refine_pixels). Returns whether any plane is
/// to be refined pixel by pixel.
bool FitNarrowPlanesApart(const GridImage& image, const CellMoments& cells, const EdgeGrids& edges,
                          const Regions& regions, GridFits& fits, NarrowWork& work) {
  const bool ray_fit = image.params.ray_fit;
  const std::size_t num_regions = regions.sums.size();
  for (std::size_t r = 0; r < num_regions; ++r) {
    if (!work.narrow[r]) continue;
    fits.sums[r] = regions.sums[r];
    if (ray_fit) fits.rays[r] = regions.rays[r];
  }
  work.apart_sums = fits.sums;
  work.apart_rays = fits.rays;
  for (const int c : edges.grids) {
    const int r = regions.cell_region[c];
    if (r < 0 || !work.narrow[r]) continue;
    const auto [cx, cy] = image.Xy(c);
    bool next_to_other_plane = false;
    for (int i = 0; i < 9; ++i) {
      const int o = image.RegionAt(regions.cell_region, cx + i % 3 - 1, cy + i / 3 - 1);
      next_to_other_plane |= o >= 0 && o != r;
    }
    if (!next_to_other_plane) continue;
    work.apart_sums[r].Subtract(cells.sums[c]);
    if (ray_fit) work.apart_rays[r].Subtract(cells.grid_rays[c]);
  }
  work.too_narrow.assign(num_regions, 0);
  work.refine_pixels.assign(num_regions, 0);
  bool any_refined = false;
  for (std::size_t r = 0; r < num_regions; ++r) {
    if (!work.narrow[r]) continue;
    if (work.apart_sums[r].k >= 0.25 * regions.sums[r].k) {
      fits.sums[r] = work.apart_sums[r];
      if (ray_fit) fits.rays[r] = work.apart_rays[r];
    } else {
      work.too_narrow[r] = 1;
      work.refine_pixels[r] = regions.sums[r].k >= kNarrowRefinePoints;
      any_refined |= work.refine_pixels[r] != 0;
    }
  }
  return any_refined;
}

/// The planes marked refine_pixels refined, plane by plane (their grids in grid order, from one
/// look at every grid).
void RefineNarrowPlanes(const GridImage& image, const CellMoments& cells, Regions& regions,
                        GridFits& fits, NarrowWork& work) {
  work.narrow_plane_grids.clear();
  for (int c = 0; c < image.num_cells; ++c) {
    const int r = regions.cell_region[c];
    if (r >= 0 && work.refine_pixels[r]) work.narrow_plane_grids.emplace_back(r, c);
  }
  std::sort(work.narrow_plane_grids.begin(), work.narrow_plane_grids.end());
  work.visit.assign(image.num_cells, -1);
  NarrowPlaneRefiner refiner(image, cells, regions, fits, work);
  for (std::size_t i = 0; i < work.narrow_plane_grids.size();) {
    const int r = work.narrow_plane_grids[i].first;
    work.narrow_grids.clear();
    for (; i < work.narrow_plane_grids.size() && work.narrow_plane_grids[i].first == r; ++i) {
      work.narrow_grids.push_back(work.narrow_plane_grids[i].second);
    }
    refiner.Refine(r, work.narrow_grids);
  }
}

}  // namespace

// A grid on a plane's border may hold another surface too, at a crease with another plane or at
// the rim of something that is no plane, and tilt a fit to all the plane's grids (most where the
// plane is narrow or seen at a grazing angle). So each plane is fitted to its interior grids; a
// plane too narrow for that (under a quarter of its points left) to all its grids but those next
// to another plane; and one too narrow for that as well keeps them all, or, from
// kNarrowRefinePoints, is refined pixel by pixel.
void FitGridPlanes(const GridImage& image, const CellMoments& cells, const EdgeGrids& edges,
                   Regions& regions, GridFits& fits) {
  NarrowWork& work = internal::ThreadScratch<NarrowWork>();
  fits.pixel_overrides.clear();
  FitInteriorGrids(image, cells, edges, regions, fits);
  // The narrow planes only (most frames have none).
  const std::size_t num_regions = regions.sums.size();
  work.narrow.assign(num_regions, 0);
  bool any_narrow = false;
  for (std::size_t r = 0; r < num_regions; ++r) {
    const double interior = fits.sums[r].k, all = regions.sums[r].k;
    work.narrow[r] = TooNarrowForInteriorFit(interior, all);
    any_narrow |= work.narrow[r] != 0;
  }
  if (!any_narrow) return;
  if (FitNarrowPlanesApart(image, cells, edges, regions, fits, work)) {
    RefineNarrowPlanes(image, cells, regions, fits, work);
  }
}

}  // namespace planeslam::detection::gbrg

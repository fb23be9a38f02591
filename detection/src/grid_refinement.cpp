// GBRG stage 3: the edge grids, the grid-level refinement with its narrow passes, and the
// regions' ray sums.
#include <algorithm>

#include "grid_pipeline.hpp"

namespace planeslam::detection::gbrg {
namespace {

/// More passes of the grid-level refinement at narrow planes, while grids move: one pass judges a
/// plane's neighbour grids against its fit as grown, which a few grids of the wall behind it can
/// tilt; each pass refits and judges again.
constexpr int kNarrowPasses = 3;

/// Whether the grid at column cx, row cy is an edge grid, with bounds checks (image border).
bool IsEdgeAtBorder(const GridImage& image, const std::vector<std::int32_t>& cell_region, int cx,
                    int cy) {
  const std::int32_t own = image.RegionAt(cell_region, cx, cy);
  bool interior = own >= 0, any_plane = own >= 0;
  for (int oy = -1; oy <= 1; ++oy) {
    for (int ox = -1; ox <= 1; ++ox) {
      const std::int32_t r = image.RegionAt(cell_region, cx + ox, cy + oy);
      if (r != own) interior = false;
      if (r >= 0) any_plane = true;
    }
  }
  return any_plane && !interior;
}

/// The grid-level refinement's buffers, reused across frames.
struct GridRefinementWork {
  std::vector<FastFit> fits;                    ///< each plane's eigen fit
  std::vector<std::uint8_t> fit_stale;          ///< per plane: fits[r] is out of date
  std::vector<std::pair<int, int>> grid_moves;  ///< (grid, plane it moves to) of a pass
  std::vector<std::int32_t> candidate_stamp;    ///< per plane (+1): last edge grid it was seen at
  std::vector<double> edge_points;              ///< per plane: the points of its edge grids
  std::vector<std::uint8_t> is_narrow;          ///< per plane (narrow passes)
  std::vector<std::uint8_t> at_narrow_plane;    ///< per grid: in or next to a narrow plane
};

/// Grid-level refinement: each edge grid goes whole to the adjacent plane (of its 8 neighbours)
/// that fits it best within tolerance (GridFitRatio); a grid of a plane only when that fits it
/// better than its own. This undoes grids that joined a plane only because they lie within its
/// noise: far from the sensor a grid's normal is noise and gets no angle test, so a plane grazing
/// a wall picks up the wall's grids along their corner. And it gives a plane the grids along its
/// rim that growth left out (classed non-planar, refused by a test against a young region's
/// plane, or left in a region too small to be a plane) when they fit it; a grid that straddles
/// two surfaces fits neither within tolerance and stays out. Candidate planes are those grown,
/// fixed during the pass, and the moves are applied after it, so the result does not depend on
/// grid order.
class GridRefiner {
 public:
  GridRefiner(const GridImage& image, const CellMoments& cells, Regions& regions,
              GridRefinementWork& work)
      : image_(image),
        cells_(cells),
        regions_(regions),
        work_(work),
        num_regions_(regions.sums.size()) {
    work_.fit_stale.assign(num_regions_, 1);
    work_.fits.resize(num_regions_);
  }

  /// One pass over the edge grids; with narrow_only (a narrow pass) only the grids at a narrow
  /// plane (work.at_narrow_plane), and only moves into or out of one (work.is_narrow). Returns
  /// whether a grid moved.
  bool RefineEdgeGrids(const EdgeGrids& edges, bool narrow_only) {
    RefitStale();
    work_.grid_moves.clear();
    // Each plane once among a grid's candidates, without a data-dependent branch: a plane is new
    // to edge grid e while its stamp is not e + 1 (stamp 0 stands for no plane, never new).
    work_.candidate_stamp.assign(num_regions_ + 1, 0);
    std::int32_t* const stamp = work_.candidate_stamp.data() + 1;
    const std::size_t num_edge = edges.grids.size();
    for (std::size_t e = 0; e < num_edge; ++e) {
      const int c = edges.grids[e];
      if (e + kRefinePrefetchAhead < num_edge) {
        const char* ahead =
            reinterpret_cast<const char*>(&cells_.sums[edges.grids[e + kRefinePrefetchAhead]]);
        __builtin_prefetch(ahead);
        __builtin_prefetch(ahead + 64);
        __builtin_prefetch(ahead + sizeof(MomentSums) - 1);
      }
      const int best = BestPlane(c, narrow_only, stamp, static_cast<std::int32_t>(e + 1));
      if (best >= 0) work_.grid_moves.emplace_back(c, best);
    }
    for (const auto& [c, to] : work_.grid_moves) {
      if (regions_.cell_region[c] >= 0) {
        regions_.sums[regions_.cell_region[c]].Subtract(cells_.sums[c]);
        work_.fit_stale[regions_.cell_region[c]] = 1;
      }
      regions_.sums[to].Merge(cells_.sums[c]);
      work_.fit_stale[to] = 1;
      regions_.cell_region[c] = to;
    }
    return !work_.grid_moves.empty();
  }

  /// Marks the narrow planes (too narrow for their interior grids) and the grids at them (their
  /// grids and their 8 neighbours). Returns whether there is any.
  bool FindNarrowPlanes(const EdgeGrids& edges) {
    work_.edge_points.assign(num_regions_, 0.0);
    for (const int c : edges.grids) {
      const int r = regions_.cell_region[c];
      if (r >= 0) work_.edge_points[r] += cells_.sums[c].k;
    }
    work_.is_narrow.assign(num_regions_, 0);
    bool any_narrow = false;
    for (std::size_t r = 0; r < num_regions_; ++r) {
      const double all = regions_.sums[r].k;
      work_.is_narrow[r] = TooNarrowForInteriorFit(all - work_.edge_points[r], all);
      any_narrow |= work_.is_narrow[r] != 0;
    }
    if (!any_narrow) return false;
    const int cells_x = image_.cells_x, cells_y = image_.cells_y;
    work_.at_narrow_plane.assign(image_.num_cells, 0);
    for (int c = 0; c < image_.num_cells; ++c) {
      const int r = regions_.cell_region[c];
      if (r < 0 || !work_.is_narrow[r]) continue;
      const auto [cx, cy] = image_.Xy(c);
      for (int oy = std::max(0, cy - 1); oy <= std::min(cells_y - 1, cy + 1); ++oy) {
        for (int ox = std::max(0, cx - 1); ox <= std::min(cells_x - 1, cx + 1); ++ox) {
          work_.at_narrow_plane[oy * cells_x + ox] = 1;
        }
      }
    }
    return true;
  }

 private:
  void RefitStale() {
    for (std::size_t i = 0; i < num_regions_; ++i) {
      if (!work_.fit_stale[i]) continue;
      work_.fits[i] = FitSums(regions_.sums[i]);
      work_.fit_stale[i] = 0;
    }
  }

  /// The plane edge grid c moves to (-1: it stays); `fresh_stamp` is unique to the grid.
  int BestPlane(int c, bool narrow_only, std::int32_t* stamp, std::int32_t fresh_stamp) {
    const int cells_x = image_.cells_x;
    const MomentSums& g = cells_.sums[c];
    const auto [cx, cy] = image_.Xy(c);
    const int own = regions_.cell_region[c];
    if (narrow_only && !work_.at_narrow_plane[c]) return -1;
    if (own < 0 && cells_.counts[c] < image_.MuOf(cx, cy)) return -1;  // too few points to tell
    // The planes of the 3 x 3 grids around, each once (bounds checks only at the image border).
    std::int32_t around[9];
    if (cx > 0 && cy > 0 && cx + 1 < cells_x && cy + 1 < image_.cells_y) {
      for (int i = 0; i < 9; ++i)
        around[i] = regions_.cell_region[c + (i / 3 - 1) * cells_x + i % 3 - 1];
    } else {
      for (int i = 0; i < 9; ++i)
        around[i] = image_.RegionAt(regions_.cell_region, cx + i % 3 - 1, cy + i / 3 - 1);
    }
    // A grid of a plane with only its own plane around (and no plane) stays: most edge grids.
    // Told before the stamps below, whose store and load per neighbour wait on each other when
    // the neighbours share a plane.
    bool own_plane_only = own >= 0;
    for (const std::int32_t r : around) own_plane_only &= (r == own) | (r < 0);
    if (own_plane_only) return -1;
    stamp[-1] = fresh_stamp;
    int candidates[9];
    int num_candidates = 0;
    for (const std::int32_t r : around) {
      candidates[num_candidates] = r;
      num_candidates += stamp[r] != fresh_stamp;
      stamp[r] = fresh_stamp;
    }
    int best = -1;
    double best_ratio = 1.0;  // beyond tolerance: no plane
    for (int i = 0; i < num_candidates; ++i) {
      const int r = candidates[i];
      const double ratio = GridFitRatio(image_, g, work_.fits[r]);
      // The lower region index wins a tie, whatever the visiting order.
      if (ratio < best_ratio || (ratio == best_ratio && best >= 0 && r < best)) {
        best_ratio = ratio;
        best = r;
      }
    }
    if (best < 0 || best == own) return -1;
    if (narrow_only && !work_.is_narrow[best] && !(own >= 0 && work_.is_narrow[own])) return -1;
    return best;
  }

  const GridImage& image_;
  const CellMoments& cells_;
  Regions& regions_;
  GridRefinementWork& work_;
  const std::size_t num_regions_;
};

}  // namespace

// In ascending grid order. Away from the image border, each row's flags come from a loop without
// branches or bounds checks, which the compiler vectorises, and are then appended without
// branches (a data-dependent branch per grid mispredicts often).
void FindEdgeGrids(const GridImage& image, const CellMoments& cells,
                   const std::vector<std::int32_t>& cell_region, EdgeGrids& edges) {
  const int cells_x = image.cells_x, cells_y = image.cells_y;
  edges.scratch.resize(image.num_cells);
  edges.flags.resize(cells_x);
  int* const out = edges.scratch.data();
  std::uint8_t* const flags = edges.flags.data();
  std::size_t n = 0;
  for (int cy = 0; cy < cells_y; ++cy) {
    const int row = cy * cells_x;
    const std::int32_t* count = cells.counts.data() + row;
    if (cy == 0 || cy + 1 == cells_y || cells_x < 3) {
      for (int cx = 0; cx < cells_x; ++cx) {
        if (count[cx] != 0 && IsEdgeAtBorder(image, cell_region, cx, cy)) out[n++] = row + cx;
      }
      continue;
    }
    const std::int32_t* mid = cell_region.data() + row;
    const std::int32_t* up = mid - cells_x;
    const std::int32_t* down = mid + cells_x;
    if (count[0] != 0 && IsEdgeAtBorder(image, cell_region, 0, cy)) out[n++] = row;
    const int last = cells_x - 1;  // a local: the flag stores (bytes) may alias a member
    for (int cx = 1; cx < last; ++cx) {
      const std::int32_t own = mid[cx];
      const std::int32_t u0 = up[cx - 1], u1 = up[cx], u2 = up[cx + 1], m0 = mid[cx - 1],
                         m2 = mid[cx + 1], d0 = down[cx - 1], d1 = down[cx], d2 = down[cx + 1];
      const bool same = (u0 == own) & (u1 == own) & (u2 == own) & (m0 == own) & (m2 == own) &
                        (d0 == own) & (d1 == own) & (d2 == own);
      const std::int32_t highest = std::max(std::max(std::max(std::max(own, u0), std::max(u1, u2)),
                                                     std::max(std::max(m0, m2), std::max(d0, d1))),
                                            d2);
      flags[cx] = (count[cx] != 0) & (highest >= 0) & !((own >= 0) & same);
    }
    for (int cx = 1; cx < last; ++cx) {
      out[n] = row + cx;
      n += flags[cx];
    }
    if (count[cells_x - 1] != 0 && IsEdgeAtBorder(image, cell_region, cells_x - 1, cy))
      out[n++] = row + cells_x - 1;
  }
  edges.grids.assign(out, out + n);
}

// One pass over every edge grid; when grids moved, passes around the narrow planes only, while
// grids move.
void RefineGrids(const GridImage& image, const CellMoments& cells, Regions& regions,
                 EdgeGrids& edges) {
  GridRefiner refiner(image, cells, regions, internal::ThreadScratch<GridRefinementWork>());
  if (regions.sums.empty() || !refiner.RefineEdgeGrids(edges, false)) return;
  FindEdgeGrids(image, cells, regions.cell_region, edges);
  for (int pass = 0; pass < kNarrowPasses; ++pass) {
    if (!refiner.FindNarrowPlanes(edges)) break;
    if (!refiner.RefineEdgeGrids(edges, true)) break;
    FindEdgeGrids(image, cells, regions.cell_region, edges);
  }
}

void SumRegionRays(const GridImage& image, const CellMoments& cells, Regions& regions) {
  const bool ray_fit = image.params.ray_fit;
  regions.rays.assign(ray_fit ? regions.sums.size() : 0, RaySums());
  if (!ray_fit) return;
  // The grids' ray sums (megabytes with 3x3 grids) have left the cache since the moments pass:
  // fetched 1 kB ahead, which the hardware prefetcher alone does not keep up with.
  for (int c = 0; c < image.num_cells; ++c) {
    __builtin_prefetch(reinterpret_cast<const char*>(cells.grid_rays.data() + c) + 1024);
    if (regions.cell_region[c] >= 0) regions.rays[regions.cell_region[c]].Add(cells.grid_rays[c]);
  }
}

}  // namespace planeslam::detection::gbrg

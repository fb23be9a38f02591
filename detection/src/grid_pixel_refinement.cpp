// GBRG stage 3b: the pixel-level boundary refinement of the edge grids.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>

#include "grid_pipeline.hpp"

namespace planeslam::detection::gbrg {
namespace {

/// The pixel-level refinement's buffers, reused across frames.
struct PixelRefinementWork {
  std::vector<float> plane_nd;  ///< each plane's n, d in float
  /// The moved pixels of one edge grid, in pixel order: (pixel, slot of the candidate plane it
  /// goes to, or the number of candidates: none).
  std::vector<std::pair<std::size_t, int>> moved_pixels;
};

/// Each valid pixel of an edge grid goes to the best-fitting candidate plane (its own and the 8
/// neighbours') when within its tolerance, else to none. Interior grids keep all their pixels.
/// Candidate planes are the ones grown (fixed during the pass, so the result does not depend on
/// grid order). "Best" is the smallest distance in units of the pixel's tolerance. Under the
/// depth model the tolerance is noise only, refine_sigmas sigma_n with sigma_n = sigma(z) |n.p|
/// / z (plane-dependent): the base gamma, which lets growth absorb a large region's gentle
/// bending, would here hand a plane the strip of the adjacent surface along their crease and the
/// mixed pixels of depth edges, which tilt its fit.
class PixelRefiner {
 public:
  PixelRefiner(const GridImage& image, const CellMoments& cells, Regions& regions,
               std::vector<std::int32_t>& labels, PixelRefinementWork& work)
      : image_(image),
        params_(image.params),
        cells_(cells),
        regions_(regions),
        labels_(labels),
        work_(work),
        choice_(image) {
    // Each plane's n, d in float, once, not per edge grid.
    work_.plane_nd.clear();
    for (const MomentSums& m : regions_.sums) AppendPlaneNd(m, work_.plane_nd);
    work_.moved_pixels.resize(static_cast<std::size_t>(image.k) * image.k);
  }

  void RefineGrid(int c) {
    const auto [cx, cy] = image_.Xy(c);
    own_ = regions_.cell_region[c];
    FindCandidates(c, cx, cy);
    y0_ = cy * image_.k;
    x0_ = cx * image_.k;
    y1_ = std::min(image_.height, y0_ + image_.k);
    x1_ = std::min(image_.width, x0_ + image_.k);
    // One copy of the pixel loop for a grid with a single candidate plane (most edge grids: a
    // plane beside no other), where BestPlane reduces to distance < tolerance (its comparison
    // multiplies each side by 1: the same result).
    if (n_adj_ == 1) {
      LabelPixels(std::true_type());
    } else {
      LabelPixels(std::false_type());
    }
    if (num_moved_ == 0) return;
    if (one_plane_) {
      MoveWholeGrid(c);
    } else {
      MovePixels(c);
    }
  }

 private:
  /// The planes of the grid and its 8 neighbours (-1: none or outside the image), read without
  /// bounds checks away from the image border, sorted and unique in adj_: the lowest region index
  /// wins distance ties. Their n, d in cand_.
  void FindCandidates(int c, int cx, int cy) {
    const int cells_x = image_.cells_x;
    int around[9];
    if (cx > 0 && cy > 0 && cx + 1 < cells_x && cy + 1 < image_.cells_y) {
      const std::int32_t* above = regions_.cell_region.data() + (c - cells_x - 1);
      for (int i = 0; i < 3; ++i) {
        around[i] = above[i];
        around[3 + i] = above[cells_x + i];
        around[6 + i] = above[2 * cells_x + i];
      }
    } else {
      for (int i = 0; i < 9; ++i)
        around[i] = image_.RegionAt(regions_.cell_region, cx + i % 3 - 1, cy + i / 3 - 1);
    }
    n_adj_ = 0;
    for (const int r : around) {
      if (r < 0) continue;
      int pos = 0;
      while (pos < n_adj_ && adj_[pos] < r) ++pos;
      if (pos < n_adj_ && adj_[pos] == r) continue;
      for (int j = n_adj_; j > pos; --j) adj_[j] = adj_[j - 1];
      adj_[pos] = r;
      ++n_adj_;
    }
    for (int i = 0; i < n_adj_; ++i) {
      std::memcpy(cand_[i], work_.plane_nd.data() + 4 * adj_[i], sizeof(cand_[i]));
    }
  }

  /// Each valid pixel's plane, and whether they all went to one (one_plane_, first_to_); the
  /// pixels that leave `own_` listed with their slot.
  template <typename SingleCandidate>
  void LabelPixels(SingleCandidate) {
    // Locals, not members, in the loop: the label stores may alias an int member.
    const Eigen::Vector3f* pts = image_.pts;
    std::int32_t* const labels = labels_.data();
    std::pair<std::size_t, int>* const moved = work_.moved_pixels.data();
    const int own = own_, n_adj = n_adj_, width = image_.width;
    const int x0 = x0_, y0 = y0_, x1 = x1_, y1 = y1_;
    const bool spherical = image_.spherical;
    int adj[9];
    std::copy(adj_, adj_ + n_adj, adj);
    int first_to = -2;  // -2: no valid pixel yet
    bool one_plane = true;
    std::size_t num_moved = 0;
    for (int y = y0; y < y1; ++y) {
      for (int x = x0; x < x1; ++x) {
        const std::size_t idx = static_cast<std::size_t>(y) * width + x;
        const Eigen::Vector3f& pf = pts[idx];
        if (!std::isfinite(pf.z())) continue;
        const float z = internal::PointDepth(pf, spherical);
        int best;
        if constexpr (SingleCandidate::value) {
          float dist, tol;
          choice_.DistanceAndTolerance(pf, choice_.RelativeNoise(z), cand_[0], dist, tol);
          best = dist < tol ? 0 : -1;
        } else {
          best = choice_.BestPlane(pf, choice_.RelativeNoise(z), &cand_[0][0], n_adj);
        }
        const int to = best >= 0 ? adj[best] : -1;
        labels[idx] = to;
        moved[num_moved] = {idx, best >= 0 ? best : n_adj};  // kept if it leaves (no branch)
        num_moved += to != own;
        if (first_to == -2) first_to = to;
        one_plane &= to == first_to;
      }
    }
    first_to_ = first_to;
    one_plane_ = one_plane;
    num_moved_ = num_moved;
  }

  /// The whole grid changes plane: move its sums.
  void MoveWholeGrid(int c) {
    if (own_ >= 0) {
      regions_.sums[own_].Subtract(cells_.sums[c]);
      if (params_.ray_fit) regions_.rays[own_].Subtract(cells_.grid_rays[c]);
    }
    if (first_to_ >= 0) {
      regions_.sums[first_to_].Merge(cells_.sums[c]);
      if (params_.ray_fit) regions_.rays[first_to_].Add(cells_.grid_rays[c]);
    }
  }

  /// Only the pixels that change plane change the sums: each moved pixel is added to the slot of
  /// where it goes (slot n_adj: to no plane); what the grid's own plane loses is all the slots
  /// together. Applied once per grid; the noise moment takes the grid's weight, as the grid's own
  /// sums do.
  void MovePixels(int c) {
    MomentSums* const gained = gained_;
    RaySums* const gained_rays = gained_rays_;
    for (int i = 0; i <= n_adj_; ++i) {
      gained[i] = MomentSums();
      gained_rays[i] = RaySums();
    }
    for (std::size_t i = 0; i < num_moved_; ++i) {
      const auto [idx, slot] = work_.moved_pixels[i];
      const Eigen::Vector3f& pf = image_.pts[idx];
      gained[slot].AddPosition(pf.x(), pf.y(), pf.z());
      const float z = internal::PointDepth(pf, image_.spherical);
      if (params_.ray_fit && z > 0.0f) gained_rays[slot].Add(pf, z, params_.RayFitWeight(z));
    }
    const double w = cells_.noise_weight[c];
    MomentSums lost;
    RaySums lost_rays;
    for (int i = 0; i <= n_adj_; ++i) {
      if (gained[i].k == 0) continue;
      gained[i].SetUniformNoise(w);
      lost.Merge(gained[i]);
      lost_rays.Add(gained_rays[i]);
      if (i == n_adj_) continue;  // the pixels that leave every plane
      regions_.sums[adj_[i]].Merge(gained[i]);
      if (params_.ray_fit) regions_.rays[adj_[i]].Add(gained_rays[i]);
    }
    if (own_ >= 0) {
      regions_.sums[own_].Subtract(lost);
      if (params_.ray_fit) regions_.rays[own_].Subtract(lost_rays);
    }
  }

  const GridImage& image_;
  const DetectionParams& params_;
  const CellMoments& cells_;
  Regions& regions_;
  std::vector<std::int32_t>& labels_;
  PixelRefinementWork& work_;
  const PixelChoice choice_;
  // The edge grid being refined: its plane, candidate planes, pixels and moves.
  int own_ = -1;
  int adj_[9];
  int n_adj_ = 0;
  float cand_[9][4];  // the candidate planes: n, d
  int x0_ = 0, y0_ = 0, x1_ = 0, y1_ = 0;
  int first_to_ = -2;  // the plane of the first valid pixel (-2: none yet)
  bool one_plane_ = true;
  std::size_t num_moved_ = 0;  // valid pixels that leave own_
  MomentSums gained_[10];      // per candidate plane of the grid (and none): what it gains
  RaySums gained_rays_[10];
};

}  // namespace

void RefinePixels(const GridImage& image, const CellMoments& cells, const EdgeGrids& edges,
                  Regions& regions, std::vector<std::int32_t>& labels) {
  PixelRefiner refiner(image, cells, regions, labels,
                       internal::ThreadScratch<PixelRefinementWork>());
  const int k = image.k, width = image.width;
  const std::size_t num_edge = edges.grids.size();
  for (std::size_t e = 0; e < num_edge; ++e) {
    // The points of an edge grid were last read by the moments pass and have left the core's
    // caches since; the edge grids come with gaps the hardware prefetcher does not follow. Fetch
    // the rows of the grid a few places ahead (first and last point of each row, and its labels,
    // for writing), and its noise weight, read when pixels leave (in an array that leaves the
    // cache as well). Here in the loop, not in a function of their own: a function that only
    // prefetches has no effect the compiler must keep.
    if (e + kRefinePrefetchAhead < num_edge) {
      const int ahead = edges.grids[e + kRefinePrefetchAhead];
      const auto [ax, ay] = image.Xy(ahead);
      const int ay1 = std::min(image.height, ay * k + k), ax1 = std::min(width, ax * k + k) - 1;
      for (int y = ay * k; y < ay1; ++y) {
        const std::size_t row = static_cast<std::size_t>(y) * width;
        __builtin_prefetch(image.pts + row + ax * k);
        __builtin_prefetch(image.pts + row + ax1);
        __builtin_prefetch(labels.data() + row + ax * k, 1);  // written below
      }
      __builtin_prefetch(&cells.noise_weight[ahead]);
    }
    refiner.RefineGrid(edges.grids[e]);
  }
}

}  // namespace planeslam::detection::gbrg

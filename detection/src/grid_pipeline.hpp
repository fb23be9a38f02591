#pragma once
// The stages of GridRegionGrowing::Detect (GBRG, see grid_region_growing.hpp) and the state they
// pass along: moments and classification, growth, refinement, merging, final fit. Each stage
// keeps its own scratch buffers (thread-local, reused across frames); what one stage hands to
// the next is declared here.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "region_common.hpp"

namespace planeslam::detection::gbrg {

/// How many edge grids ahead the refinement, merge and fits prefetch their data.
constexpr std::size_t kRefinePrefetchAhead = 4;

/// The grid image of one frame: the cloud, the settings, and the k x k grids laid over it.
struct GridImage {
  GridImage(const datasets::OrganizedCloud& cloud, const DetectionParams& params,
            const GridParams& grid)
      : cloud(cloud),
        params(params),
        grid(grid),
        pts(cloud.points.data()),
        width(cloud.width),
        height(cloud.height),
        k(grid.CellSize()),
        cells_x((width + k - 1) / k),
        cells_y((height + k - 1) / k),
        num_cells(cells_x * cells_y),
        spherical(cloud.model == datasets::SensorModel::kSpherical),
        depth_model(params.model == ThresholdModel::kDepth),
        mu(grid.EffectiveMu()),
        inv_cells_x(1.0 / std::max(cells_x, 1)) {}

  const datasets::OrganizedCloud& cloud;
  const DetectionParams& params;
  const GridParams& grid;
  const Eigen::Vector3f* pts;
  int width, height;
  int k;  ///< grid side [px]
  int cells_x, cells_y, num_cells;
  bool spherical;    ///< ranges from a scanner's centre, not depths along a camera's axis
  bool depth_model;  ///< tolerances from the sensor's depth noise (else constant)
  double mu;         ///< the least valid points of a non-sparse k x k grid

  /// A grid's column and row without an integer division (tens of cycles, in the per-grid loops
  /// of growth and refinement): (c + 0.5) / cells_x is at least 0.5 / cells_x from an integer,
  /// far beyond its rounding.
  std::pair<int, int> Xy(int c) const {
    const int cy = static_cast<int>((c + 0.5) * inv_cells_x);
    return std::pair<int, int>(c - cy * cells_x, cy);
  }
  /// The least points of a non-sparse grid at grid column cx, row cy: mu, or in the grid-level
  /// pipeline mu scaled by the share of a k x k grid that a grid cut by the image border covers.
  double MuOf(int cx, int cy) const {
    if (!grid.grid_level) return mu;
    const int w = std::min(k, width - cx * k), h = std::min(k, height - cy * k);
    return std::max(3.0, std::ceil(mu * w * h / (k * k)));
  }
  /// The region of the grid at column cx, row cy in `cell_region` (-1: none, or outside).
  std::int32_t RegionAt(const std::vector<std::int32_t>& cell_region, int cx, int cy) const {
    return cx >= 0 && cy >= 0 && cx < cells_x && cy < cells_y ? cell_region[cy * cells_x + cx] : -1;
  }

 private:
  double inv_cells_x;
};

/// Plane of one planar grid and its per-grid test tolerances, in float: 32 bytes, half a cache
/// line (the growth reads one per tested grid, in an order that leaves the cache often). Float
/// places the centre to a micrometre at 10 m, against tolerances of millimetres.
struct alignas(32) CellInfo {
  Eigen::Vector3f n = Eigen::Vector3f::Zero();  ///< oriented unit normal (d >= 0)
  Eigen::Vector3f m = Eigen::Vector3f::Zero();  ///< mass centre [m]
  float cos_tol = 1.0f;  ///< eta test: |n_GR . n_g| must exceed this (-1 = no test)
  float sin_tol = 0.0f;  ///< sine of the same tolerance (widening it by a tilt needs both)
};

/// Stage 1, moments and classification: what every later stage reads of each grid.
struct CellMoments {
  std::vector<MomentSums> sums;      ///< K, S, Q and the noise moment W
  std::vector<double> noise_weight;  ///< w = (sigma(z) / z)^2 at the grid's centre
  std::vector<std::int32_t> counts;  ///< valid pixels (its K, compact for scans)
  std::vector<int> partly_valid;     ///< the grids with an invalid pixel, ascending
  std::vector<RaySums> grid_rays;    ///< ray sums of the grid's pixels (ray fit)
  std::vector<CellClass> classes;
  std::vector<CellInfo> info;  ///< of the planar grids
  /// Seed keys of the planar grids (in grid order; the growth consumes them).
  std::vector<std::uint64_t> seeds;
  std::vector<std::uint64_t> seed_keys;  ///< each planar grid's seed key (grid-level pipeline)
};

/// Sums every grid's moments and classifies it, a row of grids at a time. Returns the time the
/// classification took [ms] (of the whole).
double ComputeCellMoments(const GridImage& image, CellMoments& cells);

/// The regions: grown by stage 2, then refined and merged.
struct Regions {
  std::vector<std::int32_t> cell_region;  ///< each grid's region (-1: none)
  std::vector<MomentSums> sums;           ///< each region's moments
  std::vector<RaySums> rays;              ///< each region's ray sums (ray fit; from stage 3)
};

/// Stage 2, growth (Algorithm 2), with the second growth of left-out grids in the grid-level
/// pipeline. Consumes cells.seeds.
void GrowRegions(const GridImage& image, CellMoments& cells, Regions& regions);

/// A grid's MSE about plane f in units of its tolerance there, refine_sigmas^2 times its
/// expected MSE along the normal (depth model) or gamma^2 (constant model): under 1, it fits.
inline double GridFitRatio(const GridImage& image, const MomentSums& g, const FastFit& f) {
  const DetectionParams& params = image.params;
  const double refine2 = params.refine_sigmas * params.refine_sigmas;
  double nqn, ns;  // the grid's squared distances to the plane: nqn - 2 d ns + K d^2
  g.AlongNormal(f.normal, nqn, ns);
  const double mse = std::max(0.0, nqn - 2.0 * f.d * ns + g.k * f.d * f.d) / g.k;
  const double tolerance2 =
      image.depth_model ? refine2 * g.ExpectedMse(f.normal) : params.gamma * params.gamma;
  return mse / std::max(tolerance2, 1e-18);
}

/// A plane whose interior grids (all 8 neighbours in it) hold under a quarter of its points: too
/// narrow for a fit to them, and refined again by the grid-level refinement's narrow passes.
inline bool TooNarrowForInteriorFit(double interior_points, double all_points) {
  return interior_points < 0.25 * all_points;
}

/// The edge grids: those with a plane among their 8 neighbours that are not themselves interior
/// grids of a plane (all 8 neighbours in their own plane), ascending. Only they can hold a pixel
/// whose plane differs from a 4-neighbour's, so the refinement, the merge's adjacency and the
/// crease pixels of the ray fit look at them only.
struct EdgeGrids {
  std::vector<int> grids;
  std::vector<int> scratch;         ///< edge grids as found (room for every grid)
  std::vector<std::uint8_t> flags;  ///< whether each grid of a row is an edge grid
};
void FindEdgeGrids(const GridImage& image, const CellMoments& cells,
                   const std::vector<std::int32_t>& cell_region, EdgeGrids& edges);

/// Stage 3a, grid-level refinement (grid-level pipeline): edge grids move whole to the plane
/// that fits them best, then again around narrow planes; `edges` follows the moves.
void RefineGrids(const GridImage& image, const CellMoments& cells, Regions& regions,
                 EdgeGrids& edges);

/// Every region's ray sums from its grids' (regions.rays; empty without the ray fit).
void SumRegionRays(const GridImage& image, const CellMoments& cells, Regions& regions);

/// Stage 3b, pixel-level boundary refinement: each valid pixel of an edge grid goes to the
/// best-fitting plane around within its tolerance, else to none; `labels` (pixels) and the
/// regions' sums follow.
void RefinePixels(const GridImage& image, const CellMoments& cells, const EdgeGrids& edges,
                  Regions& regions, std::vector<std::int32_t>& labels);

/// Pixel labels from a value per grid (the invalid pixels of a grid with a value >= 0 get -1).
void ExpandToPixels(const GridImage& image, const CellMoments& cells,
                    const std::int32_t* grid_values, std::vector<std::int32_t>& pixels);

/// Stage 4, merging: where regions meet in `region_image` (grids with grid labels, else
/// pixels), and, with merge_regions, the regions describing one surface merged. A grid image is
/// relabelled; a pixel image is left as it is, with the map to merged regions in `label_root`.
internal::RegionBorders MergeRegions(const GridImage& image, const EdgeGrids& edges,
                                     bool grid_labels, std::vector<std::int32_t>& region_image,
                                     Regions& regions, std::vector<std::int32_t>& label_root);

/// What each plane of whole grids is fitted to in the grid-level pipeline, and the pixels whose
/// label differs from their grid's.
struct GridFits {
  std::vector<MomentSums> sums;
  std::vector<RaySums> rays;
  /// Pixel labels that differ from their grid's: (pixel, a grid of their plane, or -1: none).
  std::vector<std::pair<std::size_t, int>> pixel_overrides;
};

/// Stage 3c, the grid-level pipeline's fits (after merging): each plane's interior grids, or
/// for a narrow plane its grids apart from the other planes, or, for one too narrow for that as
/// well, its pixels after the narrow-plane pixel refinement and block fit.
void FitGridPlanes(const GridImage& image, const CellMoments& cells, const EdgeGrids& edges,
                   Regions& regions, GridFits& fits);

/// Stage 5, final fit: each plane refitted from its pixels (eigen or ray fit) into `out`.
/// `fits` is null without the grid-level pipeline's fits.
void FinalFit(const GridImage& image, const CellMoments& cells, bool grid_labels,
              std::vector<std::int32_t>& region_image, Regions& regions,
              const internal::RegionBorders& borders, const GridFits* fits,
              const std::vector<std::int32_t>& label_root, Segmentation& out);

/// A plane as the pixel refinement compares pixels with it: the eigen fit of `m` as n, d in
/// float, appended to `planes`.
inline void AppendPlaneNd(const MomentSums& m, std::vector<float>& planes) {
  const FastFit f = FitSums(m);
  planes.insert(planes.end(), {static_cast<float>(f.normal.x()), static_cast<float>(f.normal.y()),
                               static_cast<float>(f.normal.z()), static_cast<float>(f.d)});
}

/// The pixel-level refinement's choice for one pixel (boundary refinement, and the narrow
/// planes): of the candidate planes (n, d: four floats each), the nearest in units of the pixel's
/// tolerance, refine_sigmas sigma_n with sigma_n = sigma(z) |n.p| / z (gamma under the constant
/// model), if within it, else -1; an earlier candidate wins a tie. Compared as
/// best_dist * tol < dist * best_tol (no division), from ratio 1 (beyond tolerance). In float:
/// at 50 m its rounding is a few micrometres, against tolerances of millimetres or more.
class PixelChoice {
 public:
  explicit PixelChoice(const GridImage& image)
      : params_(image.params),
        depth_model_(image.depth_model),
        s0_(image.params.sigma0),
        refine_sigmas_f_(static_cast<float>(image.params.refine_sigmas)),
        sigma_z2_f_(static_cast<float>(image.params.sigma_z2)),
        gamma_f_(static_cast<float>(image.params.gamma)) {}

  /// sigma(z) / z
  float RelativeNoise(float z) const {
    return s0_ == 0.0 ? sigma_z2_f_ * z : static_cast<float>(params_.Sigma(z) / z);
  }
  /// A pixel's distance to one candidate plane (n, d) and its tolerance there.
  void DistanceAndTolerance(const Eigen::Vector3f& pf, float rel, const float* plane, float& dist,
                            float& tol) const {
    const float np = plane[0] * pf.x() + plane[1] * pf.y() + plane[2] * pf.z();
    tol = depth_model_ ? refine_sigmas_f_ * rel * std::abs(np) : gamma_f_;
    dist = std::abs(np - plane[3]);
  }
  int BestPlane(const Eigen::Vector3f& pf, float rel, const float* planes, int n) const {
    int best = -1;
    float best_dist = 1.0f, best_tol = 1.0f;
    for (int i = 0; i < n; ++i) {
      float dist, tol;
      DistanceAndTolerance(pf, rel, planes + 4 * i, dist, tol);
      // Selects rather than branches: which candidate wins is data, not a pattern.
      const bool better = dist * best_tol < best_dist * tol;
      best_dist = better ? dist : best_dist;
      best_tol = better ? tol : best_tol;
      best = better ? i : best;
    }
    return best;
  }

 private:
  const DetectionParams& params_;
  bool depth_model_;
  double s0_;
  float refine_sigmas_f_, sigma_z2_f_, gamma_f_;
};

}  // namespace planeslam::detection::gbrg

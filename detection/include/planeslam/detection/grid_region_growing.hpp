#pragma once
/// Grid-based region growing, GBRG (Xiao et al. 2011, Section III). Detect runs as a pipeline of
/// stages (detection/src/grid_pipeline.hpp):
///
/// 1. Moments and classification. The range image is cut into k x k grids (paper: 3 x 3);
///    per-grid moments K, S, Q (and the ray sums, for the ray fit) are summed straight from the
///    cloud in one pass (no per-pixel normals). Each grid is classified from its scatter
///    eigenvalues l1 <= l2 <= l3: K < mu sparse, l2 <= alpha l3 linear, l1 <= beta l2 planar,
///    else spherical (Section III-A; with the depth threshold model a grid whose residual is
///    within the sensor noise is planar too).
/// 2. Growth. Seeds are the unassigned planar grids in order of increasing MSE (ties by grid
///    index, row-major); the order is computed once by sorting (MSE, index) keys, which pops
///    exactly what the paper's min-heap would, with less work. Under the depth threshold model the
///    key adds the ray noise leaking through the grid's normal uncertainty (far noisy grids seed
///    last). A region grows breadth-first over 4-neighbour grids (the grid image's left/right/up/
///    down). 4- rather than 8-neighbours: a diagonal grid touches the region in one corner pixel
///    only, so it adds no evidence of continuity, and 8-neighbours leak across thin diagonal
///    edges; every grid of a 4-connected plane is still reached. A candidate g joins when
///      n_GR . n_g > cos(eta),  |n_GR . (m_GR - m_g)| < gamma,  MSE(GR u g) < epsilon
///    (Algorithm 2 line 8). The merged moments are updated on every join (eq. 5); the plane is
///    refitted from them (eq. 6) after every join with refit_interval = 1, as in the paper, or,
///    with refit_interval = 0 (adaptive, the default), after every max(1, N/64) joins of a region
///    of N grids: in between, the angle and coplanarity tests use the current plane (which moves
///    by O(1/N) a grid), and the MSE test first tries the MSE about the current normal, an upper
///    bound of the merged MSE; only when that bound fails is the exact eigen solve done, so the
///    MSE test accepts what the paper's accepts (as PBRG's adaptive refit; under the depth model
///    up to epsilon's own slight dependence on the normal). A rejected grid may be tested again
///    when another of its neighbours joins (the region's plane has changed since). Regions of >=
///    ceil(theta / k^2) grids are planes; the grids of smaller (uncertain) regions leave G as in
///    the paper: they neither seed nor join later regions (their pixels may still be given to a
///    plane by the refinement; the grid-level pipeline grows those that fit no plane once more).
/// 3. Refinement, beyond the paper. The pixel-level refinement (refine_boundary, on by default)
///    gives each valid pixel of a grid on a plane's edge to the best-fitting plane among its 8
///    neighbour grids when |n.p - d| < gamma(z) (with refine_sigmas), else to none. The grid-level
///    pipeline (method grid-fast) moves whole edge grids to the plane that fits them best instead,
///    again around planes too narrow for an interior fit, and fits each plane to its interior
///    grids; a plane seen edge-on, as narrow as a grid or two, gets the pixel-level refinement
///    and a fit of its pixels.
/// 4. Merging: adjacent (and, with merge_disjoint, disjoint) regions describing one surface are
///    merged.
/// 5. Final fit: each plane is refitted from all its pixels (eigen fit, or the ray fit).
#include <string>

#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/plane_detector.hpp"

namespace planeslam::detection {

/// GBRG-specific parameters (Section III-A).
struct GridParams {
  int cell_size = 0;  ///< grid side k [px]; 0 = 3 (the paper), or 6 in the grid-level pipeline
  int mu = 0;         ///< min valid points of a non-sparse grid; 0 = k^2 - k + 1 (paper: 7 for 3x3)
  double alpha = 0.006;    ///< linear when l2 <= alpha l3 (paper value)
  double beta = 0.4;       ///< planar when l1 <= beta l2 (paper value)
  int refit_interval = 0;  ///< 1 = refit the plane on every join (paper); N = every N; 0 = adaptive
  /// The grid-level pipeline (method grid-fast): refinement moves whole grids, so every pixel
  /// keeps its grid's label, and the steps that keep planes seen edge-on, as narrow as a grid,
  /// whole and exact run (see GridRegionGrowing). Off: the paper's growth, then the pixel-level
  /// refinement as set in DetectionParams.
  bool grid_level = false;

  int CellSize() const { return cell_size > 0 ? cell_size : grid_level ? 6 : 3; }
  int EffectiveMu() const {
    const int k = CellSize();
    return mu > 0 ? mu : k * k - k + 1;
  }
  std::vector<std::string> Validate() const;
};

/// Method `grid-fast`: the grid-level pipeline (grid_level) in place of the pixel-level
/// refinement, with 6x6 grids unless grid.cell_size is set: as wide as a far wall seen edge-on.
void UseFastVariant(DetectionParams& params, GridParams& grid);

class GridRegionGrowing : public PlaneDetector {
 public:
  GridRegionGrowing(const DetectionParams& params, const GridParams& grid, std::string name = "");
  std::string Name() const override { return name_; }
  Segmentation Detect(const datasets::OrganizedCloud& cloud) const override;

 private:
  DetectionParams params_;
  GridParams grid_;
  std::string name_;
};

}  // namespace planeslam::detection

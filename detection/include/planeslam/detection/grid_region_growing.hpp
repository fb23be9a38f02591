#pragma once
/// Grid-based region growing, GBRG (Xiao et al. 2011, Section III).
///
/// 1. The range image is cut into k x k grids (paper: 3 x 3); per-grid moments K, S, Q are summed
///    straight from the cloud in one pass (no per-pixel normals).
/// 2. Each grid is classified from its scatter eigenvalues l1 <= l2 <= l3: K < mu sparse,
///    l2 <= alpha l3 linear, l1 <= beta l2 planar, else spherical (Section III-A; with the depth
///    threshold model a grid whose residual is within the sensor noise is planar too).
/// 3. Seeds are the unassigned planar grids in order of increasing MSE (ties by grid index,
///    row-major); the order is computed once by sorting (MSE, index) keys, which pops exactly what
///    the paper's min-heap would, with less work. Under the depth threshold model the key adds
///    the ray noise leaking through the grid's normal uncertainty (far noisy grids seed last). A
///    region grows breadth-first over 4-neighbour grids (the grid image's left/right/up/down). 4-
///    rather than 8-neighbours: a diagonal grid touches the region in one corner pixel only, so it
///    adds no evidence of continuity, and 8-neighbours leak across thin diagonal edges; every grid
///    of a 4-connected plane is still reached. A candidate g joins when
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
///    plane by the refinement; regrow_left_out grows those that fit no plane once more).
/// 4. Beyond the paper (both optional, on by default): boundary refinement gives each valid pixel
///    of a grid outside every plane, with a plane among its 8 neighbour grids, to the best-fitting
///    such plane when |n.p - d| < gamma(z) (with refine_sigmas); then adjacent regions describing
///    one surface are merged. Final planes are refitted from all their pixels.
#include <string>

#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/plane_detector.hpp"

namespace planeslam::detection {

/// GBRG-specific parameters (Section III-A).
struct GridParams {
  int cell_size = 3;  ///< grid side k [px] (paper: 3)
  int mu = 0;         ///< min valid points of a non-sparse grid; 0 = k^2 - k + 1 (paper: 7 for 3x3)
  double alpha = 0.006;    ///< linear when l2 <= alpha l3 (paper value)
  double beta = 0.4;       ///< planar when l1 <= beta l2 (paper value)
  int refit_interval = 0;  ///< 1 = refit the plane on every join (paper); N = every N; 0 = adaptive
  /// Before any pixel-level refinement: each grid at a plane's border, in a plane (when another
  /// fits it better) or outside every plane (with at least mu points), goes whole to the adjacent
  /// plane that fits it best within tolerance; without the pixel-level refinement, each plane is
  /// then fitted to its interior grids (all 8 neighbours in the plane).
  bool refine_grids = false;
  /// Depth model: a growing region whose second-smallest spread l2 / K is under this many times
  /// its ray noise (trace W / K) has no resolved normal yet (on a far wall, where the noise
  /// exceeds a grid's width, a strip of grids fits the plane across the strip): it joins grids by
  /// the MSE test alone, without the angle and coplanarity tests. 0 = off (every region's normal
  /// counts from its seed on).
  double unresolved_spread = 0.0;
  /// Without the pixel-level refinement (detection.refine_boundary off): the smallest plane, in
  /// points of its whole grids, too narrow for any whole-grid fit (a column or two of grids) that
  /// gets the pixel-level refinement on its grids and the grids around them. Smaller ones keep
  /// whole grids: on real frames most are slivers of a neighbour (about 3 a TUM frame,
  /// 400-1800 px with 6x6 grids), which all together took 0.26-0.33 ms a frame to refine, a
  /// tenth of grid-fast's time, for no measured gain against grid3's planes.
  double narrow_refine_points = 2000.0;
  /// Without the pixel-level refinement: a plane of narrow_refine_points or more whose interior
  /// grids hold under this fraction of its points gets that pixel-level refinement as well,
  /// instead of a fit to its interior grids or to its grids apart from the other planes (0 =
  /// only the planes too narrow for both). Such fits keep the near, wide end of a plane seen
  /// along (the synthetic room's right wall turned 22 deg, Kinect noise, grid3-fast: 2.7 cm off
  /// fitted to 1134 of its 2313 px, 630 px wide; 2.1 cm off fitted to the third of its 3447 px in
  /// interior grids, 634 px wide).
  double refine_interior_fraction = 0.0;
  /// A grid cut by the image's right or bottom border (width or height not a multiple of k) is
  /// sparse below mu scaled by its share of a k x k grid, instead of below mu itself, which it may
  /// not even hold (640 px wide with 6x6 grids: the last column is 4 px wide, 24 px against mu
  /// 31, so whatever it shows belongs to no plane without the pixel-level refinement).
  bool border_grid_mu = false;
  /// After growth, the grids of regions too small to be planes (R', which leave G in the paper)
  /// that fit none of the planes next to them (the grid-level refinement's test) seed and grow a
  /// second time, among themselves, in seed order. A far wall seen edge-on and as narrow as a
  /// grid has the smallest grid MSEs (its noise lies along it), so it seeds before the wall
  /// behind; with a normal not yet resolved, its regions take that wall's grids by the MSE test
  /// alone and stay under theta. After the wall behind has grown, only its own grids are left to
  /// it.
  bool regrow_left_out = false;
  /// With the grid-level refinement: up to this many more passes of it, while grids move, over
  /// the grids in and next to a narrow plane (one whose edge grids hold over 3/4 of its points),
  /// each moving grids into or out of a narrow plane only. One pass gives a plane only the grids
  /// next to it as grown and judges them against its fit as grown: a wall seen edge-on as narrow
  /// as a grid stays in pieces across grids the growth refused, or keeps the grids of the wall
  /// behind it that tilted it (the synthetic room's right wall turned 23.75 deg with Kinect
  /// noise, 6x6 grids: 0.3-2.6 deg off, or mostly missed, on 16 of 20 noise draws at 646 and 650
  /// px wide). The planes are refitted between passes.
  int narrow_passes = 0;

  int EffectiveMu() const { return mu > 0 ? mu : cell_size * cell_size - cell_size + 1; }
  std::vector<std::string> Validate() const;
};

/// GBRG's grid-level pipeline, keeping the grid size: regions without a resolved normal grown by
/// the MSE test alone (unresolved_spread 2), the grid-level refinement in place of the
/// pixel-level one, so that every pixel keeps its grid's label and each plane is fitted (along
/// the rays, as set) to its interior grids; only a plane of narrow_refine_points or more too
/// narrow for any such fit (a column or two of grids) gets the pixel-level refinement on its
/// grids and those around them. Merging and the ray fit stay as set.
void UseGridLevelPipeline(DetectionParams& params, GridParams& grid);
/// Method `grid-fast`: the grid-level pipeline with 6x6 grids, as wide as a far wall seen
/// edge-on: border grids with a scaled mu (border_grid_mu), a second growth of the grids left
/// out (regrow_left_out) and 3 more refinement passes at narrow planes (narrow_passes). Without
/// the first two, the synthetic room's right wall turned 20-23.5 deg with Kinect noise (6-10 px
/// wide at 3.5-3.8 m) was mostly missed or 2-14 cm off on 6 of the 30 renders where it has 2000
/// px or more; without the third, on 21 of 2310 renders of 19-24 deg and 630-650 px (ten noise
/// draws each), with it on 1 (as grid3-fast).
void UseFastVariant(DetectionParams& params, GridParams& grid);
/// Method `grid3-fast`: the grid-level pipeline with the paper's 3x3 grids. A narrow plane's
/// whole 3x3 grids hold about half of it (the room's noise-free right wall turned 23 deg:
/// 1143 of its 2298 px), so the pixel-level refinement of narrow planes starts at 1000 points,
/// and at an interior of under half of a plane's points (refine_interior_fraction 0.5).
void UseFast3x3Variant(DetectionParams& params, GridParams& grid);

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

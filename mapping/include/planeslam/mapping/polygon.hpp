#pragma once
/// Polygon outlines of map planes: 2D bases on planes, concave hulls of plane points,
/// Douglas-Peucker simplification, ear-clipping triangulation.
///
/// Concave hull method (ConcaveHull): occupancy-grid boundary tracing, chosen over alpha shapes
/// because the points of one plane are dense samples of a region (10^4..10^5 points): a grid is
/// linear in the number of points, needs no Delaunay triangulation, is deterministic, tolerates
/// duplicate and collinear points, and its resolution (the cell) is the one knob that matters.
///  1. Bin the points into square cells (cell size given, or chosen so that a cell holds about
///     `target_points_per_cell` points at the observed density). The grid is placed so that the
///     extreme samples lie 2/3 of a cell into the outermost cells, where step 3 puts the contour.
///  2. Smooth the binary occupancy with a 3x3 box filter. Small gaps of the sampling (an empty cell
///     among occupied ones) stay inside; isolated outlier cells fall below the iso level.
///  3. Marching squares at iso level 11/18 on the smoothed field. On a straight edge the last
///     occupied cell has smoothed value 6/9 and the next 3/9, so the contour passes 1/6 cell
///     outside the centre of the boundary cells: close to the true edge, which lies uniformly
///     within those cells (an outline along the cells' outer edges would overestimate the area by
///     half a cell times the perimeter). 11/18 lies strictly between the possible values 5/9 and
///     6/9, so the contour never passes through a sample and is a set of disjoint simple closed
///     curves.
///  4. Keep the outer boundary of every separate region (a curve inside no other curve): holes
///     (unseen parts inside a region) are filled, and regions inside holes are then covered by
///     their surroundings. Make each counter-clockwise, simplify it with Douglas-Peucker, and fall
///     back to a smaller tolerance if simplification made it non-simple.
/// A plane seen in separate pieces (a floor seen only along the walls) so keeps every piece.
#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace planeslam::mapping {

/// An orthonormal 2D frame on the plane n.p = d: p = origin + u x + v y, with u x v = n.
struct PlaneBasis {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit normal n
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();   ///< n d, the plane point closest to 0 [m]
  Eigen::Vector3d u = Eigen::Vector3d::UnitX();       ///< first in-plane axis
  Eigen::Vector3d v = Eigen::Vector3d::UnitY();       ///< second in-plane axis

  /// Plane coordinates of the orthogonal projection of p [m] (inline: the map projects every
  /// sample of a plane whenever its extent is rebuilt).
  Eigen::Vector2d Project(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d r = p - origin;
    return {u.dot(r), v.dot(r)};
  }
  /// The 3D point on the plane with plane coordinates xy [m].
  Eigen::Vector3d Unproject(const Eigen::Vector2d& xy) const;
};

/// A deterministic basis for the plane n.p = d (n need not be unit; it is normalised). u is n x e
/// normalised, e being the coordinate axis least aligned with n. CheckError when n is zero or not
/// finite.
PlaneBasis MakePlaneBasis(const Eigen::Vector3d& normal, double d);

/// Concave hull settings.
struct PolygonConfig {
  /// [m] grid cell of the hull (stretched per axis by a fraction to fit the extent, see the file
  /// comment); 0 = automatic from the point density
  double cell_size = 0.0;
  double target_points_per_cell =
      6.0;                          ///< [points] mean count per cell when cell_size is automatic
  double simplify_tolerance = 0.0;  ///< [m] Douglas-Peucker tolerance; 0 = half a cell, < 0 = none
  int max_grid_cells = 4000000;     ///< [cells] the cell grows when the grid would be larger

  std::vector<std::string> Validate() const;
};

/// A simple polygon, counter-clockwise, without the first vertex repeated at the end.
struct Polygon2 {
  std::vector<Eigen::Vector2d> vertices;
  double area = 0.0;  ///< [m^2] shoelace area (> 0)
};

/// The outline of a planar region: one simple polygon per separate part, holes filled.
struct RegionOutline {
  std::vector<Polygon2> parts;  ///< largest first; disjoint, none inside another
  double area = 0.0;            ///< sum of the parts' areas [m^2]
  double cell_size = 0.0;       ///< [m] cell used by ConcaveHull (geometric mean of its sides)

  /// False when the points did not give a region (too few, degenerate).
  bool valid() const { return !parts.empty(); }
};

/// Concave hull of dense samples of a planar region, one polygon per separate part (method in the
/// file comment). Returns no parts (no exception) for fewer than 3 finite points or a degenerate
/// region. CheckError when `config` is invalid.
RegionOutline ConcaveHull(const std::vector<Eigen::Vector2d>& points,
                          const PolygonConfig& config = {});

/// True when p lies inside the closed polygon (even-odd rule; either orientation).
bool PointInPolygon(const Eigen::Vector2d& p, const std::vector<Eigen::Vector2d>& polygon);

/// Signed shoelace area: > 0 for counter-clockwise vertices [m^2].
double SignedArea(const std::vector<Eigen::Vector2d>& polygon);

/// True when no two non-adjacent edges intersect or touch and no edge has zero length.
bool IsSimplePolygon(const std::vector<Eigen::Vector2d>& polygon);

/// Douglas-Peucker simplification of a closed polygon: every removed vertex lies within `tolerance`
/// of the simplified outline. Keeps at least 3 vertices when the input has them.
std::vector<Eigen::Vector2d> SimplifyClosedPolygon(const std::vector<Eigen::Vector2d>& polygon,
                                                   double tolerance);

/// Ear-clipping triangulation of a simple polygon (either orientation). Returns index triples into
/// `polygon`, counter-clockwise, n - 2 of them; their areas sum to |SignedArea(polygon)|.
std::vector<std::array<int, 3>> TriangulatePolygon(const std::vector<Eigen::Vector2d>& polygon);

}  // namespace planeslam::mapping

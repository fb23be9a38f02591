// Plane bases, concave hulls (grid + marching squares), Douglas-Peucker, ear clipping.
#include "planeslam/mapping/polygon.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <unordered_map>
#include <utility>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::mapping {

// ---------------------------------------------------------------------------------------------
// Plane basis

Eigen::Vector3d PlaneBasis::Unproject(const Eigen::Vector2d& xy) const {
  return origin + u * xy.x() + v * xy.y();
}

PlaneBasis MakePlaneBasis(const Eigen::Vector3d& normal, double d) {
  const double norm = normal.norm();
  PLANESLAM_CHECK(std::isfinite(norm) && norm > 0.0 && std::isfinite(d),
                  "plane normal must be finite and non-zero");
  PlaneBasis basis;
  basis.normal = normal / norm;
  // n.p = d with n not unit is (n/|n|).p = d/|n|.
  basis.origin = basis.normal * (d / norm);
  // The axis least aligned with n gives the best-conditioned cross product (ties: lowest index).
  int axis = 0;
  for (int i = 1; i < 3; ++i) {
    if (std::abs(basis.normal[i]) < std::abs(basis.normal[axis])) axis = i;
  }
  basis.u = basis.normal.cross(Eigen::Vector3d::Unit(axis)).normalized();
  basis.v = basis.normal.cross(basis.u);  // u x v = n
  return basis;
}

// ---------------------------------------------------------------------------------------------
// Polygon predicates

namespace {

double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

/// > 0 when a, b, c turn counter-clockwise.
double Orient(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return Cross(b - a, c - a);
}

/// c on segment ab, given that a, b, c are collinear.
bool OnSegment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return std::min(a.x(), b.x()) <= c.x() && c.x() <= std::max(a.x(), b.x()) &&
         std::min(a.y(), b.y()) <= c.y() && c.y() <= std::max(a.y(), b.y());
}

int Sign(double v) { return (v > 0) - (v < 0); }

/// Closed segments ab and cd share at least one point. Segments with disjoint bounding boxes
/// never do (whatever the rounding of the orientations), which lets IsSimplePolygon test only
/// the pairs whose boxes overlap.
bool SegmentsIntersect(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c,
                       const Eigen::Vector2d& d) {
  if (std::max(a.x(), b.x()) < std::min(c.x(), d.x()) ||
      std::max(c.x(), d.x()) < std::min(a.x(), b.x()) ||
      std::max(a.y(), b.y()) < std::min(c.y(), d.y()) ||
      std::max(c.y(), d.y()) < std::min(a.y(), b.y())) {
    return false;
  }
  const int o1 = Sign(Orient(a, b, c));
  const int o2 = Sign(Orient(a, b, d));
  const int o3 = Sign(Orient(c, d, a));
  const int o4 = Sign(Orient(c, d, b));
  if (o1 != o2 && o3 != o4 && o1 * o2 <= 0 && o3 * o4 <= 0) {
    if (o1 != 0 || o2 != 0) return true;
  }
  if (o1 == 0 && OnSegment(a, b, c)) return true;
  if (o2 == 0 && OnSegment(a, b, d)) return true;
  if (o3 == 0 && OnSegment(c, d, a)) return true;
  if (o4 == 0 && OnSegment(c, d, b)) return true;
  return false;
}

}  // namespace

double SignedArea(const std::vector<Eigen::Vector2d>& polygon) {
  const std::size_t n = polygon.size();
  if (n < 3) return 0.0;
  // Shoelace relative to the first vertex: fewer cancellations far from the origin.
  double twice = 0.0;
  const Eigen::Vector2d& o = polygon[0];
  for (std::size_t i = 1; i + 1 < n; ++i) twice += Cross(polygon[i] - o, polygon[i + 1] - o);
  return 0.5 * twice;
}

bool IsSimplePolygon(const std::vector<Eigen::Vector2d>& polygon) {
  const std::size_t n = polygon.size();
  if (n < 3) return false;
  for (std::size_t i = 0; i < n; ++i) {
    if (polygon[i] == polygon[(i + 1) % n]) return false;
  }
  if (SignedArea(polygon) == 0.0) return false;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[(i + 1) % n];
    // Adjacent edge (b, c): only a fold-back (c on the line through a, b, behind b) is illegal.
    const Eigen::Vector2d& c = polygon[(i + 2) % n];
    if (Orient(a, b, c) == 0.0 && (a - b).dot(c - b) > 0.0) return false;
  }
  // Non-adjacent edges must not meet. Only edges whose x ranges overlap can: a sweep over the
  // edges by their left ends pairs each with those starting before it ends.
  struct Edge {
    double x0, x1, y0, y1;
    std::size_t i;  ///< from vertex i to vertex i + 1
  };
  std::vector<Edge> edges(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[(i + 1) % n];
    edges[i] = {std::min(a.x(), b.x()), std::max(a.x(), b.x()), std::min(a.y(), b.y()),
                std::max(a.y(), b.y()), i};
  }
  std::sort(edges.begin(), edges.end(), [](const Edge& e, const Edge& f) {
    return e.x0 < f.x0 || (e.x0 == f.x0 && e.i < f.i);
  });
  for (std::size_t k = 0; k < n; ++k) {
    const Edge& e = edges[k];
    for (std::size_t m = k + 1; m < n && edges[m].x0 <= e.x1; ++m) {
      const Edge& f = edges[m];
      const std::size_t i = std::min(e.i, f.i), j = std::max(e.i, f.i);
      if (j - i < 2 || (i == 0 && j == n - 1)) continue;  // adjacent edges
      if (f.y0 > e.y1 || e.y0 > f.y1) continue;
      if (SegmentsIntersect(polygon[i], polygon[(i + 1) % n], polygon[j], polygon[(j + 1) % n])) {
        return false;
      }
    }
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Douglas-Peucker

namespace {

double DistanceToSegment(const Eigen::Vector2d& p, const Eigen::Vector2d& a,
                         const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  const double length2 = ab.squaredNorm();
  if (length2 == 0.0) return (p - a).norm();
  const double t = std::clamp((p - a).dot(ab) / length2, 0.0, 1.0);
  return (p - (a + t * ab)).norm();
}

/// Marks the vertices kept on the open chain first..last (indices modulo n, last after first).
void SimplifyChain(const std::vector<Eigen::Vector2d>& polygon, std::size_t first, std::size_t last,
                   double tolerance, std::vector<char>& keep) {
  const std::size_t n = polygon.size();
  std::vector<std::pair<std::size_t, std::size_t>> stack{{first, last}};  // unwrapped indices
  while (!stack.empty()) {
    const auto [s, e] = stack.back();
    stack.pop_back();
    if (e <= s + 1) continue;
    const Eigen::Vector2d& a = polygon[s % n];
    const Eigen::Vector2d& b = polygon[e % n];
    double worst = -1.0;
    std::size_t worst_index = s;
    for (std::size_t k = s + 1; k < e; ++k) {
      const double distance = DistanceToSegment(polygon[k % n], a, b);
      if (distance > worst) {
        worst = distance;
        worst_index = k;
      }
    }
    if (worst > tolerance) {
      keep[worst_index % n] = 1;
      stack.push_back({s, worst_index});
      stack.push_back({worst_index, e});
    }
  }
}

}  // namespace

std::vector<Eigen::Vector2d> SimplifyClosedPolygon(const std::vector<Eigen::Vector2d>& polygon,
                                                   double tolerance) {
  const std::size_t n = polygon.size();
  if (n <= 3 || !(tolerance > 0.0)) return polygon;
  // Split the ring at vertex 0 and the vertex farthest from it: both are kept, each half is an
  // open Douglas-Peucker chain.
  std::size_t far = 0;
  double far_distance = -1.0;
  for (std::size_t i = 1; i < n; ++i) {
    const double distance = (polygon[i] - polygon[0]).squaredNorm();
    if (distance > far_distance) {
      far_distance = distance;
      far = i;
    }
  }
  std::vector<char> keep(n, 0);
  keep[0] = keep[far] = 1;
  SimplifyChain(polygon, 0, far, tolerance, keep);
  SimplifyChain(polygon, far, n, tolerance, keep);
  std::vector<Eigen::Vector2d> out;
  for (std::size_t i = 0; i < n; ++i) {
    if (keep[i]) out.push_back(polygon[i]);
  }
  if (out.size() < 3) {
    // Two kept vertices: add the one farthest from their line so the result still has an area.
    std::size_t best = 0;
    double best_distance = -1.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double distance = DistanceToSegment(polygon[i], polygon[0], polygon[far]);
      if (!keep[i] && distance > best_distance) {
        best_distance = distance;
        best = i;
      }
    }
    keep[best] = 1;
    out.clear();
    for (std::size_t i = 0; i < n; ++i) {
      if (keep[i]) out.push_back(polygon[i]);
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Concave hull

std::vector<std::string> PolygonConfig::Validate() const {
  std::vector<std::string> problems;
  if (!(cell_size >= 0.0) || !std::isfinite(cell_size))
    problems.push_back("cell_size must be >= 0");
  if (!(target_points_per_cell >= 1.0) || !std::isfinite(target_points_per_cell)) {
    problems.push_back("target_points_per_cell must be >= 1");
  }
  if (!std::isfinite(simplify_tolerance)) problems.push_back("simplify_tolerance must be finite");
  if (max_grid_cells < 64) problems.push_back("max_grid_cells must be >= 64");
  return problems;
}

namespace {

/// Default Douglas-Peucker tolerance in cells. A whole cell cuts convex corners off enough to lose
/// a noticeable part of the area; half a cell keeps the area close to the grid's while an outline
/// still needs only a few tens of vertices.
constexpr double kAutoToleranceCells = 0.5;

struct Bounds {
  Eigen::Vector2d min;
  Eigen::Vector2d max;
};

struct Grid {
  double cell = 0.0;     ///< nominal cell [m]
  Eigen::Vector2d size;  ///< cell width and height [m], within a few percent of `cell`
  Eigen::Vector2d min;   ///< corner of cell (0, 0)
  std::int64_t width = 0;
  std::int64_t height = 0;
};

/// Cells of about `cell` placed so that the extreme samples (which lie on the region's boundary)
/// sit 2/3 of a cell into the outermost cells: there the contour of step 3 (header) passes exactly
/// through them. Anchoring the grid at the extreme samples instead would put the contour a third of
/// a cell inside on those sides.
Grid MakeGrid(const Bounds& bounds, double cell, std::int64_t max_cells) {
  Grid grid;
  const Eigen::Vector2d extent = bounds.max - bounds.min;
  for (;;) {
    grid.cell = cell;
    std::int64_t counts[2];
    for (int axis = 0; axis < 2; ++axis) {
      // n cells of size extent / (n - 2/3): the extremes at 1/3 and n - 1/3 cells.
      const auto n = std::max<std::int64_t>(
          1, static_cast<std::int64_t>(std::llround(extent[axis] / cell + 2.0 / 3.0)));
      counts[axis] = n;
      grid.size[axis] =
          extent[axis] > 0.0 ? extent[axis] / (static_cast<double>(n) - 2.0 / 3.0) : cell;
      grid.min[axis] = bounds.min[axis] - grid.size[axis] / 3.0;
    }
    grid.width = counts[0];
    grid.height = counts[1];
    // Room for the 2-sample padding of the contour field.
    if ((grid.width + 4) * (grid.height + 4) <= max_cells) return grid;
    cell *= 1.25;
  }
}

/// Occupancy (0/1) of the cells, row-major width x height.
std::vector<std::uint8_t> Occupancy(const std::vector<Eigen::Vector2d>& points, const Grid& grid,
                                    std::size_t* occupied) {
  std::vector<std::uint8_t> occ(static_cast<std::size_t>(grid.width * grid.height), 0);
  std::size_t count = 0;
  for (const auto& p : points) {
    const auto x = std::min<std::int64_t>(
        grid.width - 1, static_cast<std::int64_t>((p.x() - grid.min.x()) / grid.size.x()));
    const auto y = std::min<std::int64_t>(
        grid.height - 1, static_cast<std::int64_t>((p.y() - grid.min.y()) / grid.size.y()));
    auto& cell = occ[static_cast<std::size_t>(y * grid.width + x)];
    count += cell == 0;
    cell = 1;
  }
  if (occupied) *occupied = count;
  return occ;
}

/// Automatic cell: about `target` points per cell at the density points / occupied area. The area
/// is estimated from the occupied cells of the previous (coarser) cell, starting from the bounding
/// box, so the estimate shrinks towards the region's own area in a few rounds.
double AutomaticCell(const std::vector<Eigen::Vector2d>& points, const Bounds& bounds,
                     double target, std::int64_t max_cells) {
  const double n = static_cast<double>(points.size());
  const Eigen::Vector2d extent = bounds.max - bounds.min;
  double area = std::max(extent.x() * extent.y(), 0.0);
  if (area == 0.0) area = std::pow(std::max(extent.x(), extent.y()), 2);
  double cell = std::sqrt(target * area / n);
  for (int round = 0; round < 4; ++round) {
    const Grid grid = MakeGrid(bounds, cell, max_cells);
    std::size_t occupied = 0;
    Occupancy(points, grid, &occupied);
    area = static_cast<double>(occupied) * grid.size.x() * grid.size.y();
    const double next = std::sqrt(target * area / n);
    if (!(next > 0.0) || std::abs(next - cell) < 0.01 * cell) break;
    cell = next;
  }
  return cell;
}

/// Closed contours of { smoothed occupancy >= 11/18 } by marching squares.
std::vector<std::vector<Eigen::Vector2d>> Contours(const std::vector<std::uint8_t>& occ,
                                                   const Grid& grid) {
  // Samples of the field: cell centres, padded by 2 so the border samples are 0 and all contours
  // close. Field value = number of occupied cells in the 3x3 block (0..9); inside = value >= 6,
  // i.e. iso 5.5 (11/18 of 9).
  const std::int64_t w = grid.width + 4;
  const std::int64_t h = grid.height + 4;
  std::vector<std::uint8_t> field(static_cast<std::size_t>(w * h), 0);
  for (std::int64_t y = 0; y < grid.height; ++y) {
    for (std::int64_t x = 0; x < grid.width; ++x) {
      if (!occ[static_cast<std::size_t>(y * grid.width + x)]) continue;
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        for (std::int64_t dx = -1; dx <= 1; ++dx) {
          ++field[static_cast<std::size_t>((y + 2 + dy) * w + (x + 2 + dx))];
        }
      }
    }
  }
  constexpr double kIso = 5.5;
  auto value = [&](std::int64_t x, std::int64_t y) {
    return static_cast<double>(field[static_cast<std::size_t>(y * w + x)]);
  };
  auto position = [&](double x, double y) {
    // Sample (x, y) is the centre of cell (x - 2, y - 2).
    return Eigen::Vector2d(grid.min.x() + (x - 1.5) * grid.size.x(),
                           grid.min.y() + (y - 1.5) * grid.size.y());
  };
  // Lattice edges: id 2 (y w + x) is (x,y)-(x+1,y), id 2 (y w + x) + 1 is (x,y)-(x,y+1).
  auto crossing = [&](std::int64_t id) {
    const std::int64_t base = id / 2;
    const std::int64_t x = base % w;
    const std::int64_t y = base / w;
    const bool horizontal = id % 2 == 0;
    const double v0 = value(x, y);
    const double v1 = horizontal ? value(x + 1, y) : value(x, y + 1);
    const double t = (kIso - v0) / (v1 - v0);  // v0 != v1: one side is inside, the other not
    return horizontal ? position(x + t, y) : position(x, y + t);
  };

  // Each crossed lattice edge joins exactly two squares' segments (a 2-regular graph = rings).
  std::unordered_map<std::int64_t, std::array<std::int64_t, 2>> links;
  auto link = [&](std::int64_t a, std::int64_t b) {
    for (auto [from, to] : {std::pair{a, b}, std::pair{b, a}}) {
      auto it = links.find(from);
      if (it == links.end()) {
        links.emplace(from, std::array<std::int64_t, 2>{to, -1});
      } else {
        it->second[1] = to;
      }
    }
  };
  for (std::int64_t y = 0; y + 1 < h; ++y) {
    for (std::int64_t x = 0; x + 1 < w; ++x) {
      const bool bl = value(x, y) > kIso, br = value(x + 1, y) > kIso;
      const bool tr = value(x + 1, y + 1) > kIso, tl = value(x, y + 1) > kIso;
      const int inside = bl + br + tr + tl;
      if (inside == 0 || inside == 4) continue;
      const std::int64_t bottom = 2 * (y * w + x);
      const std::int64_t top = 2 * ((y + 1) * w + x);
      const std::int64_t left = 2 * (y * w + x) + 1;
      const std::int64_t right = 2 * (y * w + x + 1) + 1;
      if (bl == tr && br == tl && bl != br) {
        // Saddle: the centre (mean of the corners) decides whether the inside corners connect.
        const double centre =
            0.25 * (value(x, y) + value(x + 1, y) + value(x + 1, y + 1) + value(x, y + 1));
        const bool centre_inside = centre > kIso;
        // Cut off the corners whose state differs from the centre.
        if (bl != centre_inside) {
          link(bottom, left);
          link(top, right);
        } else {
          link(bottom, right);
          link(top, left);
        }
        continue;
      }
      std::int64_t ends[2];
      int k = 0;
      if (bl != br) ends[k++] = bottom;
      if (br != tr) ends[k++] = right;
      if (tl != tr) ends[k++] = top;
      if (bl != tl) ends[k++] = left;
      link(ends[0], ends[1]);
    }
  }

  // Walk the rings in a fixed order (sorted start ids) for determinism.
  std::vector<std::int64_t> ids;
  ids.reserve(links.size());
  for (const auto& entry : links) ids.push_back(entry.first);
  std::sort(ids.begin(), ids.end());
  std::unordered_map<std::int64_t, bool> visited;
  std::vector<std::vector<Eigen::Vector2d>> rings;
  for (std::int64_t start : ids) {
    if (visited[start]) continue;
    std::vector<Eigen::Vector2d> ring;
    std::int64_t previous = -1;
    std::int64_t current = start;
    while (!visited[current]) {
      visited[current] = true;
      ring.push_back(crossing(current));
      const auto& next = links.at(current);
      const std::int64_t following = next[0] != previous ? next[0] : next[1];
      previous = current;
      current = following;
    }
    rings.push_back(std::move(ring));
  }
  return rings;
}

}  // namespace

namespace {

/// Whether the ray from p towards +x crosses edge (a, b). Half-open in y: a ray through a vertex
/// counts the edges on one side of it only.
bool RayCrosses(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return (a.y() > p.y()) != (b.y() > p.y()) &&
         p.x() < a.x() + (p.y() - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
}

/// PointInPolygon for many points against one large polygon: its edges are listed per row of a
/// division of its y range, each in the rows its y interval spans, and a point tests only the
/// edges of its row. An edge outside the row cannot span the point's y, so it could not cross.
class PolygonRows {
 public:
  explicit PolygonRows(const std::vector<Eigen::Vector2d>& polygon) : polygon_(polygon) {
    const std::size_t n = polygon.size();
    y0_ = y1_ = polygon.front().y();
    for (const auto& v : polygon) y0_ = std::min(y0_, v.y()), y1_ = std::max(y1_, v.y());
    rows_ = std::max<int>(1, static_cast<int>(n / 8));
    height_ = (y1_ - y0_) / rows_;
    if (!(height_ > 0.0)) rows_ = 1, height_ = 1.0;
    std::vector<std::pair<int, int>> spans(n);  // rows of edge (i, i - 1)
    first_.assign(static_cast<std::size_t>(rows_) + 1, 0);
    for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
      spans[i] = {Row(std::min(polygon[i].y(), polygon[j].y())),
                  Row(std::max(polygon[i].y(), polygon[j].y()))};
      for (int r = spans[i].first; r <= spans[i].second; ++r) ++first_[r + 1];
    }
    for (int r = 0; r < rows_; ++r) first_[r + 1] += first_[r];
    edges_.resize(first_.back());
    std::vector<std::size_t> fill(first_.begin(), first_.end() - 1);
    for (std::size_t i = 0; i < n; ++i) {
      for (int r = spans[i].first; r <= spans[i].second; ++r) edges_[fill[r]++] = i;
    }
  }

  /// PointInPolygon(p, polygon).
  bool Contains(const Eigen::Vector2d& p) const {
    if (!(p.y() >= y0_ && p.y() < y1_)) return false;  // no edge spans p.y
    const std::size_t n = polygon_.size();
    bool inside = false;
    const int r = Row(p.y());
    for (std::size_t k = first_[r]; k < first_[r + 1]; ++k) {
      const std::size_t i = edges_[k];
      if (RayCrosses(p, polygon_[i], polygon_[i == 0 ? n - 1 : i - 1])) inside = !inside;
    }
    return inside;
  }

 private:
  /// Monotonic in y, so an edge's rows run from its lower end's row to its upper end's.
  int Row(double y) const {
    return std::min(rows_ - 1, static_cast<int>(std::max(0.0, (y - y0_) / height_)));
  }

  const std::vector<Eigen::Vector2d>& polygon_;
  double y0_, y1_, height_;
  int rows_;
  std::vector<std::size_t> first_;  ///< edges_[first_[r], first_[r + 1]) span row r
  std::vector<std::size_t> edges_;  ///< edge i joins vertices i and i - 1
};

}  // namespace

bool PointInPolygon(const Eigen::Vector2d& p, const std::vector<Eigen::Vector2d>& polygon) {
  bool inside = false;
  const std::size_t n = polygon.size();
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    if (RayCrosses(p, polygon[i], polygon[j])) inside = !inside;
  }
  return inside;
}

namespace {

/// Counter-clockwise and Douglas-Peucker simplified; the marching squares ring when every
/// simplification crossed itself (a thin part), since that ring is simple by construction.
Polygon2 SimplifiedPart(std::vector<Eigen::Vector2d> ring, double tolerance) {
  if (SignedArea(ring) < 0.0) std::reverse(ring.begin(), ring.end());
  Polygon2 part;
  part.vertices = ring;
  if (tolerance > 0.0) {
    for (int attempt = 0; attempt < 8; ++attempt, tolerance *= 0.5) {
      auto candidate = SimplifyClosedPolygon(ring, tolerance);
      if (IsSimplePolygon(candidate)) {
        part.vertices = std::move(candidate);
        break;
      }
    }
  }
  part.area = SignedArea(part.vertices);
  return part;
}

}  // namespace

RegionOutline ConcaveHull(const std::vector<Eigen::Vector2d>& points, const PolygonConfig& config) {
  const auto problems = config.Validate();
  PLANESLAM_CHECK(problems.empty(), "invalid PolygonConfig: " << problems.front());
  RegionOutline result;
  std::vector<Eigen::Vector2d> finite;
  finite.reserve(points.size());
  for (const auto& p : points) {
    if (p.allFinite()) finite.push_back(p);
  }
  if (finite.size() < 3) return result;
  Bounds bounds{finite[0], finite[0]};
  for (const auto& p : finite) {
    bounds.min = bounds.min.cwiseMin(p);
    bounds.max = bounds.max.cwiseMax(p);
  }
  const Eigen::Vector2d extent = bounds.max - bounds.min;
  if (!(std::max(extent.x(), extent.y()) > 0.0)) return result;

  const std::int64_t max_cells = config.max_grid_cells;
  const double cell = config.cell_size > 0.0
                          ? config.cell_size
                          : AutomaticCell(finite, bounds, config.target_points_per_cell, max_cells);
  const Grid grid = MakeGrid(bounds, cell, max_cells);
  result.cell_size = std::sqrt(grid.size.x() * grid.size.y());
  const auto occ = Occupancy(finite, grid, nullptr);
  const auto rings = Contours(occ, grid);
  // The rings are disjoint simple curves, so one vertex tells whether a ring lies inside another.
  const double tolerance = config.simplify_tolerance == 0.0
                               ? kAutoToleranceCells * grid.size.minCoeff()
                               : config.simplify_tolerance;
  // A ring can lie only inside a ring enclosing more area, and within its bounding box: only
  // those are tested.
  std::vector<double> ring_area(rings.size());
  std::vector<Eigen::AlignedBox2d> ring_box(rings.size());
  for (std::size_t i = 0; i < rings.size(); ++i) {
    ring_area[i] = std::abs(SignedArea(rings[i]));
    for (const Eigen::Vector2d& v : rings[i]) ring_box[i].extend(v);
  }
  // A large ring (a plane's outer boundary) is tested against each of its holes: its edges are
  // indexed by row the first time.
  std::vector<std::unique_ptr<PolygonRows>> ring_rows(rings.size());
  const auto inside_ring = [&](const Eigen::Vector2d& p, std::size_t j) {
    if (rings[j].size() < 64) return PointInPolygon(p, rings[j]);
    if (!ring_rows[j]) ring_rows[j] = std::make_unique<PolygonRows>(rings[j]);
    return ring_rows[j]->Contains(p);
  };
  for (std::size_t i = 0; i < rings.size(); ++i) {
    if (rings[i].size() < 3) continue;
    bool nested = false;
    for (std::size_t j = 0; j < rings.size() && !nested; ++j) {
      nested = ring_area[j] > ring_area[i] && rings[j].size() >= 3 &&
               ring_box[j].contains(rings[i].front()) && inside_ring(rings[i].front(), j);
    }
    if (nested) continue;
    Polygon2 part = SimplifiedPart(rings[i], tolerance);
    if (part.vertices.size() < 3 || !(part.area > 0.0)) continue;
    result.area += part.area;
    result.parts.push_back(std::move(part));
  }
  // Largest first; the rings come in a fixed order, so ties keep a deterministic order too.
  std::stable_sort(result.parts.begin(), result.parts.end(),
                   [](const Polygon2& a, const Polygon2& b) { return a.area > b.area; });
  return result;
}

// ---------------------------------------------------------------------------------------------
// Ear clipping

std::vector<std::array<int, 3>> TriangulatePolygon(const std::vector<Eigen::Vector2d>& polygon) {
  const int n = static_cast<int>(polygon.size());
  std::vector<std::array<int, 3>> triangles;
  if (n < 3) return triangles;
  triangles.reserve(static_cast<std::size_t>(n - 2));
  // Work on a counter-clockwise ring of indices (doubly linked).
  std::vector<int> order(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) order[static_cast<std::size_t>(i)] = i;
  if (SignedArea(polygon) < 0.0) std::reverse(order.begin(), order.end());
  std::vector<int> prev(static_cast<std::size_t>(n)), next(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    prev[static_cast<std::size_t>(k)] = (k + n - 1) % n;
    next[static_cast<std::size_t>(k)] = (k + 1) % n;
  }
  auto at = [&](int k) -> const Eigen::Vector2d& {
    return polygon[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])];
  };
  auto is_ear = [&](int k) {
    const int p = prev[static_cast<std::size_t>(k)];
    const int q = next[static_cast<std::size_t>(k)];
    const Eigen::Vector2d& a = at(p);
    const Eigen::Vector2d& b = at(k);
    const Eigen::Vector2d& c = at(q);
    if (Orient(a, b, c) <= 0.0) return false;  // reflex or flat
    // No other remaining vertex in the closed triangle (only reflex ones can be).
    for (int m = next[static_cast<std::size_t>(q)]; m != p; m = next[static_cast<std::size_t>(m)]) {
      const Eigen::Vector2d& v = at(m);
      if (v == a || v == b || v == c) continue;
      if (Orient(a, b, v) >= 0.0 && Orient(b, c, v) >= 0.0 && Orient(c, a, v) >= 0.0) return false;
    }
    return true;
  };
  int remaining = n;
  int k = 0;
  int misses = 0;
  while (remaining > 3) {
    if (is_ear(k) || misses > remaining) {
      if (misses > remaining) {
        // Numerically degenerate rest (no strict ear): clip the most convex vertex to finish.
        double best = -std::numeric_limits<double>::infinity();
        int start = k;
        int m = k;
        do {
          const double o = Orient(at(prev[static_cast<std::size_t>(m)]), at(m),
                                  at(next[static_cast<std::size_t>(m)]));
          if (o > best) {
            best = o;
            k = m;
          }
          m = next[static_cast<std::size_t>(m)];
        } while (m != start);
      }
      const int p = prev[static_cast<std::size_t>(k)];
      const int q = next[static_cast<std::size_t>(k)];
      triangles.push_back({order[static_cast<std::size_t>(p)], order[static_cast<std::size_t>(k)],
                           order[static_cast<std::size_t>(q)]});
      next[static_cast<std::size_t>(p)] = q;
      prev[static_cast<std::size_t>(q)] = p;
      --remaining;
      misses = 0;
      k = p;  // the neighbours' ear status changed; start there
    } else {
      ++misses;
      k = next[static_cast<std::size_t>(k)];
    }
  }
  const int p = prev[static_cast<std::size_t>(k)];
  const int q = next[static_cast<std::size_t>(k)];
  triangles.push_back({order[static_cast<std::size_t>(p)], order[static_cast<std::size_t>(k)],
                       order[static_cast<std::size_t>(q)]});
  return triangles;
}

}  // namespace planeslam::mapping

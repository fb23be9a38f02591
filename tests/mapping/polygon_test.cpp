#include "planeslam/mapping/polygon.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>
#include <random>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::mapping {
namespace {

using Points = std::vector<Eigen::Vector2d>;
using Inside = std::function<bool(const Eigen::Vector2d&)>;

/// Uniform random samples of the region `inside` within its bounding box [0,w] x [0,h].
Points SampleRegion(const Inside& inside, double w, double h, std::size_t count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(0.0, w), uy(0.0, h);
  Points points;
  while (points.size() < count) {
    const Eigen::Vector2d p(ux(rng), uy(rng));
    if (inside(p)) points.push_back(p);
  }
  return points;
}

/// L-shape: 4 x 3 minus the top-right 2.5 x 2 block; area 12 - 5 = 7 m^2.
bool InsideL(const Eigen::Vector2d& p) { return !(p.x() > 1.5 && p.y() > 1.0); }
/// 3 x 2 rectangle with a 1 x 1.2 notch cut into the middle of its top side; area 6 - 1.2 = 4.8.
bool InsideNotch(const Eigen::Vector2d& p) { return !(p.x() > 1.0 && p.x() < 2.0 && p.y() > 0.8); }

double TriangulatedArea(const Points& polygon) {
  double area = 0.0;
  for (const auto& t : TriangulatePolygon(polygon)) {
    area += 0.5 * ((polygon[t[1]] - polygon[t[0]]).x() * (polygon[t[2]] - polygon[t[0]]).y() -
                   (polygon[t[1]] - polygon[t[0]]).y() * (polygon[t[2]] - polygon[t[0]]).x());
  }
  return area;
}

/// One part of an outline: counter-clockwise, simple, triangulated exactly.
void CheckPart(const Polygon2& hull, double true_area, const std::string& what) {
  EXPECT_NEAR(hull.area, true_area, 0.05 * true_area) << what;
  EXPECT_NEAR(SignedArea(hull.vertices), hull.area, 1e-12);  // counter-clockwise
  EXPECT_GT(hull.area, 0.0);
  EXPECT_TRUE(IsSimplePolygon(hull.vertices)) << what;
  const auto triangles = TriangulatePolygon(hull.vertices);
  EXPECT_EQ(triangles.size(), hull.vertices.size() - 2);
  EXPECT_NEAR(TriangulatedArea(hull.vertices), hull.area, 1e-9 * hull.area) << what;
  // Simplification keeps the outline small (a rectilinear shape needs few corners).
  EXPECT_LT(hull.vertices.size(), 60u) << what;
}

/// The samples of one region give one part, and the outline's area is that part's.
void CheckHull(const Points& points, double true_area, const std::string& what,
               const PolygonConfig& config = {}) {
  const RegionOutline outline = ConcaveHull(points, config);
  ASSERT_EQ(outline.parts.size(), 1u) << what;
  EXPECT_EQ(outline.area, outline.parts[0].area);
  CheckPart(outline.parts[0], true_area, what + " cell " + std::to_string(outline.cell_size));
}

TEST(ConcaveHull, LShapeAndNotchedRectangleAreasWithinFivePercent) {
  CheckHull(SampleRegion(InsideL, 4.0, 3.0, 20000, 1), 7.0, "L 20k");
  CheckHull(SampleRegion(InsideNotch, 3.0, 2.0, 20000, 2), 4.8, "notch 20k");
  CheckHull(SampleRegion(InsideL, 4.0, 3.0, 100000, 3), 7.0, "L 100k");
  CheckHull(SampleRegion(InsideNotch, 3.0, 2.0, 5000, 4), 4.8, "notch 5k");
}

TEST(ConcaveHull, NotchIsResolved) {
  // A convex hull would report 6 m^2 for the notched rectangle; the concave hull must not contain
  // the notch's centre.
  const RegionOutline hull = ConcaveHull(SampleRegion(InsideNotch, 3.0, 2.0, 20000, 5));
  ASSERT_EQ(hull.parts.size(), 1u);
  EXPECT_FALSE(PointInPolygon({1.5, 1.4}, hull.parts[0].vertices));  // the notch's centre
  EXPECT_TRUE(PointInPolygon({0.5, 1.4}, hull.parts[0].vertices));
  EXPECT_TRUE(PointInPolygon({1.5, 0.4}, hull.parts[0].vertices));
}

TEST(ConcaveHull, SeparateRegionsArePartsAndHolesAreFilled) {
  // Three pieces of one plane metres apart (a floor seen along the walls): three parts, largest
  // first, each with its own area.
  Points pieces = SampleRegion([](const Eigen::Vector2d&) { return true; }, 2.0, 1.0, 8000, 11);
  for (const auto& p :
       SampleRegion([](const Eigen::Vector2d&) { return true; }, 1.0, 1.0, 4000, 12)) {
    pieces.push_back(p + Eigen::Vector2d(4.0, 3.0));
  }
  for (const auto& p :
       SampleRegion([](const Eigen::Vector2d&) { return true; }, 0.5, 1.0, 2000, 13)) {
    pieces.push_back(p + Eigen::Vector2d(-3.0, 0.0));
  }
  const RegionOutline outline = ConcaveHull(pieces);
  ASSERT_EQ(outline.parts.size(), 3u);
  CheckPart(outline.parts[0], 2.0, "2 x 1 piece");
  CheckPart(outline.parts[1], 1.0, "1 x 1 piece");
  CheckPart(outline.parts[2], 0.5, "0.5 x 1 piece");
  EXPECT_TRUE(PointInPolygon({4.5, 3.5}, outline.parts[1].vertices));
  EXPECT_NEAR(outline.area, outline.parts[0].area + outline.parts[1].area + outline.parts[2].area,
              1e-12);

  // A 4 x 4 frame around an unseen 2 x 2 hole holding a 1 x 1 island: one part, the hole filled
  // (outlines have no holes), the island inside it covered by that part.
  const RegionOutline framed = ConcaveHull(SampleRegion(
      [](const Eigen::Vector2d& p) {
        const Eigen::Vector2d c = p - Eigen::Vector2d(2.0, 2.0);
        const double r = c.cwiseAbs().maxCoeff();
        return r > 1.0 || r < 0.5;
      },
      4.0, 4.0, 40000, 14));
  ASSERT_EQ(framed.parts.size(), 1u);
  CheckPart(framed.parts[0], 16.0, "frame with a hole and an island");
}

TEST(ConcaveHull, ManyHolesWithIslandsInALargeRegion) {
  // A disk of radius 5 with a 3 x 3 array of unseen 1.2 x 1.2 holes, each holding a 0.4 x 0.4
  // island: the outer ring (a staircase round the disk) has hundreds of vertices, and every hole
  // and island is tested against it.
  const auto inside = [](const Eigen::Vector2d& p) {
    if ((p - Eigen::Vector2d(5.0, 5.0)).norm() > 5.0) return false;
    const Eigen::Vector2d q = p - Eigen::Vector2d(2.0, 2.0);
    if (q.minCoeff() < 0.0 || q.maxCoeff() >= 6.0) return true;
    const Eigen::Vector2d c = q - 2.0 * (q / 2.0).array().floor().matrix() - Eigen::Vector2d(1, 1);
    const double r = c.cwiseAbs().maxCoeff();
    return r > 0.6 || r < 0.2;
  };
  const RegionOutline outline = ConcaveHull(SampleRegion(inside, 10.0, 10.0, 200000, 15));
  ASSERT_EQ(outline.parts.size(), 1u);  // holes filled, islands covered
  EXPECT_NEAR(outline.parts[0].area, 25.0 * M_PI, 0.05 * 25.0 * M_PI);
}

TEST(Polygon, SimplicityMatchesEveryPairOnLatticePolygons) {
  // Random polygons with vertices on a 6 x 6 integer lattice (many collinear, touching and
  // overlapping edges, all exact in double) against a test of every pair of edges in integers.
  const auto orient = [](const Eigen::Vector2i& a, const Eigen::Vector2i& b,
                         const Eigen::Vector2i& c) {
    const long v = static_cast<long>(b.x() - a.x()) * (c.y() - a.y()) -
                   static_cast<long>(b.y() - a.y()) * (c.x() - a.x());
    return (v > 0) - (v < 0);
  };
  const auto on = [](const Eigen::Vector2i& a, const Eigen::Vector2i& b, const Eigen::Vector2i& c) {
    return std::min(a.x(), b.x()) <= c.x() && c.x() <= std::max(a.x(), b.x()) &&
           std::min(a.y(), b.y()) <= c.y() && c.y() <= std::max(a.y(), b.y());
  };
  const auto meet = [&](const Eigen::Vector2i& a, const Eigen::Vector2i& b,
                        const Eigen::Vector2i& c, const Eigen::Vector2i& d) {
    const int o1 = orient(a, b, c), o2 = orient(a, b, d), o3 = orient(c, d, a),
              o4 = orient(c, d, b);
    if (o1 * o2 < 0 && o3 * o4 < 0) return true;
    return (o1 == 0 && on(a, b, c)) || (o2 == 0 && on(a, b, d)) || (o3 == 0 && on(c, d, a)) ||
           (o4 == 0 && on(c, d, b));
  };
  std::mt19937 rng(21);
  std::uniform_int_distribution<int> coordinate(0, 5), size(3, 40);
  int simple = 0;
  for (int draw = 0; draw < 3000; ++draw) {
    std::vector<Eigen::Vector2i> v(static_cast<std::size_t>(size(rng)));
    for (auto& p : v) p = {coordinate(rng), coordinate(rng)};
    if (draw % 3 == 0) {  // star-shaped around the centre: often simple
      std::sort(v.begin(), v.end(), [](const Eigen::Vector2i& a, const Eigen::Vector2i& b) {
        return std::atan2(2 * a.y() - 5, 2 * a.x() - 5) < std::atan2(2 * b.y() - 5, 2 * b.x() - 5);
      });
    }
    const std::size_t n = v.size();
    Points polygon;
    for (const auto& p : v) polygon.emplace_back(p.x(), p.y());
    bool expected = SignedArea(polygon) != 0.0;
    for (std::size_t i = 0; i < n && expected; ++i) {
      const auto &a = v[i], &b = v[(i + 1) % n], &c = v[(i + 2) % n];
      if (a == b) expected = false;
      if (orient(a, b, c) == 0 && (a - b).dot(c - b) > 0) expected = false;
      for (std::size_t j = i + 2; j < n && expected; ++j) {
        if (i == 0 && j == n - 1) continue;
        if (meet(a, b, v[j], v[(j + 1) % n])) expected = false;
      }
    }
    simple += expected;
    EXPECT_EQ(IsSimplePolygon(polygon), expected) << draw;
  }
  EXPECT_GT(simple, 100);  // both answers were exercised
}

TEST(ConcaveHull, RotatedLatticeSamplesAndADisk) {
  // Range-image-like regular sampling of a rotated 2 x 1 rectangle with a second, smaller blob: a
  // part of its own, after the larger one.
  Points points;
  const double angle = 0.5;
  const Eigen::Rotation2Dd R(angle);
  for (double x = 0.0; x <= 2.0; x += 0.01) {
    for (double y = 0.0; y <= 1.0; y += 0.01) points.push_back(R * Eigen::Vector2d(x, y));
  }
  for (double x = 5.0; x <= 5.3; x += 0.01) {
    for (double y = 5.0; y <= 5.3; y += 0.01) points.push_back({x, y});
  }
  const RegionOutline two = ConcaveHull(points);
  ASSERT_EQ(two.parts.size(), 2u);
  CheckPart(two.parts[0], 2.0, "rotated lattice rectangle");
  EXPECT_NEAR(two.parts[1].area, 0.3 * 0.3, 0.2 * 0.3 * 0.3);  // a few cells: coarser
  EXPECT_TRUE(PointInPolygon({5.15, 5.15}, two.parts[1].vertices));

  Points disk;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  while (disk.size() < 30000) {
    const Eigen::Vector2d p(u(rng), u(rng));
    if (p.squaredNorm() <= 1.0) disk.push_back(p + Eigen::Vector2d(100.0, -50.0));
  }
  const RegionOutline hull = ConcaveHull(disk);
  ASSERT_EQ(hull.parts.size(), 1u);
  EXPECT_NEAR(hull.area, M_PI, 0.05 * M_PI);
  EXPECT_TRUE(IsSimplePolygon(hull.parts[0].vertices));
}

TEST(ConcaveHull, DeterministicAndDegenerateInputs) {
  const Points points = SampleRegion(InsideL, 4.0, 3.0, 10000, 6);
  const RegionOutline a = ConcaveHull(points);
  const RegionOutline b = ConcaveHull(points);
  ASSERT_EQ(a.parts.size(), 1u);
  ASSERT_EQ(b.parts.size(), 1u);
  EXPECT_EQ(a.parts[0].vertices, b.parts[0].vertices);

  EXPECT_FALSE(ConcaveHull({}).valid());
  EXPECT_FALSE(ConcaveHull({{0, 0}, {1, 1}}).valid());
  Points line;
  for (int i = 0; i < 1000; ++i) line.push_back({0.001 * i, 0.002 * i});
  EXPECT_FALSE(ConcaveHull(line).valid());
  Points same(500, Eigen::Vector2d(1, 2));
  EXPECT_FALSE(ConcaveHull(same).valid());
  // Non-finite points are ignored.
  Points with_nan = points;
  with_nan.push_back({std::nan(""), 0.0});
  const RegionOutline c = ConcaveHull(with_nan);
  ASSERT_EQ(c.parts.size(), 1u);
  EXPECT_EQ(c.parts[0].vertices, a.parts[0].vertices);

  PolygonConfig bad;
  bad.cell_size = -1;
  EXPECT_THROW(ConcaveHull(points, bad), CheckError);
}

TEST(ConcaveHull, ExplicitCellAndNoSimplification) {
  PolygonConfig config;
  config.cell_size = 0.05;
  config.simplify_tolerance = -1.0;  // raw marching squares outline
  const RegionOutline outline = ConcaveHull(SampleRegion(InsideL, 4.0, 3.0, 20000, 8), config);
  ASSERT_EQ(outline.parts.size(), 1u);
  // The cell is stretched per axis to fit the extent (by well under 2% here).
  EXPECT_NEAR(outline.cell_size, 0.05, 0.02 * 0.05);
  const Polygon2& hull = outline.parts[0];
  EXPECT_NEAR(hull.area, 7.0, 0.05 * 7.0);
  EXPECT_GT(hull.vertices.size(), 100u);
  EXPECT_TRUE(IsSimplePolygon(hull.vertices));
  EXPECT_NEAR(TriangulatedArea(hull.vertices), hull.area, 1e-9 * hull.area);
}

TEST(Polygon, SimplicityPredicate) {
  EXPECT_TRUE(IsSimplePolygon({{0, 0}, {1, 0}, {1, 1}, {0, 1}}));
  EXPECT_FALSE(IsSimplePolygon({{0, 0}, {1, 1}, {1, 0}, {0, 1}}));          // bow tie
  EXPECT_FALSE(IsSimplePolygon({{0, 0}, {2, 0}, {1, 0}, {1, 1}}));          // fold back
  EXPECT_FALSE(IsSimplePolygon({{0, 0}, {1, 0}, {1, 0}, {0, 1}}));          // repeated vertex
  EXPECT_FALSE(IsSimplePolygon({{0, 0}, {2, 0}, {2, 2}, {1, 0}, {0, 2}}));  // vertex on an edge
  EXPECT_FALSE(IsSimplePolygon({{0, 0}, {1, 0}}));
}

TEST(Polygon, DouglasPeuckerKeepsOutlineWithinTolerance) {
  // A noisy square outline, 400 vertices.
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> noise(-0.004, 0.004);
  Points ring;
  for (int side = 0; side < 4; ++side) {
    for (int k = 0; k < 100; ++k) {
      const double t = k / 100.0;
      Eigen::Vector2d p = side == 0   ? Eigen::Vector2d(t, 0)
                          : side == 1 ? Eigen::Vector2d(1, t)
                          : side == 2 ? Eigen::Vector2d(1 - t, 1)
                                      : Eigen::Vector2d(0, 1 - t);
      ring.push_back(p + Eigen::Vector2d(noise(rng), noise(rng)));
    }
  }
  const Points simple = SimplifyClosedPolygon(ring, 0.01);
  EXPECT_EQ(simple.size(), 4u);
  EXPECT_NEAR(SignedArea(simple), 1.0, 0.02);
  EXPECT_EQ(SimplifyClosedPolygon(ring, 0.0), ring);
  // Even a huge tolerance leaves a polygon with an area.
  EXPECT_EQ(SimplifyClosedPolygon(ring, 10.0).size(), 3u);
}

TEST(Polygon, EarClippingOfConcaveAndClockwisePolygons) {
  // A comb (deeply concave) and the same clockwise.
  Points comb{{0, 0}, {5, 0}, {5, 3}, {4, 3}, {4, 1}, {3, 1},
              {3, 3}, {2, 3}, {2, 1}, {1, 1}, {1, 3}, {0, 3}};
  const double area = SignedArea(comb);
  EXPECT_NEAR(area, 15.0 - 2 * 2 * 1, 1e-12);
  auto triangles = TriangulatePolygon(comb);
  EXPECT_EQ(triangles.size(), comb.size() - 2);
  EXPECT_NEAR(TriangulatedArea(comb), area, 1e-12);
  for (const auto& t : triangles) {
    EXPECT_GT(SignedArea({comb[t[0]], comb[t[1]], comb[t[2]]}), 0.0);  // CCW, not degenerate
  }
  Points clockwise(comb.rbegin(), comb.rend());
  triangles = TriangulatePolygon(clockwise);
  EXPECT_EQ(triangles.size(), comb.size() - 2);
  double sum = 0;
  for (const auto& t : triangles)
    sum += SignedArea({clockwise[t[0]], clockwise[t[1]], clockwise[t[2]]});
  EXPECT_NEAR(sum, area, 1e-12);
  // Collinear vertices on an edge still give n - 2 triangles with the right total area.
  Points square_with_midpoints{{0, 0}, {1, 0}, {2, 0}, {2, 2}, {1, 2}, {0, 2}};
  EXPECT_EQ(TriangulatePolygon(square_with_midpoints).size(), 4u);
  EXPECT_NEAR(TriangulatedArea(square_with_midpoints), 4.0, 1e-12);
}

TEST(PlaneBasis, OrthonormalRightHandedAndRoundTrips) {
  std::mt19937 rng(4);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Vector3d n(normal(rng), normal(rng), normal(rng));
    const double d = 3.0 * normal(rng);
    const PlaneBasis basis = MakePlaneBasis(n, d);
    EXPECT_NEAR(basis.normal.norm(), 1.0, 1e-12);
    EXPECT_NEAR(basis.u.norm(), 1.0, 1e-12);
    EXPECT_NEAR(basis.v.norm(), 1.0, 1e-12);
    EXPECT_NEAR(basis.u.dot(basis.normal), 0.0, 1e-12);
    EXPECT_NEAR(basis.u.cross(basis.v).dot(basis.normal), 1.0, 1e-12);
    // The origin is on the plane n.p = d.
    EXPECT_NEAR(n.dot(basis.origin), d, 1e-9 * (1 + std::abs(d)));
    const Eigen::Vector2d xy(normal(rng), normal(rng));
    const Eigen::Vector3d p = basis.Unproject(xy);
    EXPECT_NEAR(n.dot(p), d, 1e-9 * (1 + std::abs(d)));
    EXPECT_NEAR((basis.Project(p) - xy).norm(), 0.0, 1e-12);
    // An off-plane point projects like its foot point.
    EXPECT_NEAR((basis.Project(p + 0.7 * basis.normal) - xy).norm(), 0.0, 1e-12);
  }
  EXPECT_THROW(MakePlaneBasis(Eigen::Vector3d::Zero(), 1.0), CheckError);
  // Determinism for an axis-aligned plane: z = 2 gets u, v in the x-y plane.
  const PlaneBasis z = MakePlaneBasis(Eigen::Vector3d::UnitZ(), 2.0);
  EXPECT_NEAR(z.u.z(), 0.0, 1e-15);
  EXPECT_EQ(z.origin, Eigen::Vector3d(0, 0, 2));
}

}  // namespace
}  // namespace planeslam::mapping

#include "planeslam/mapping/polygon.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
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

void CheckHull(const Points& points, double true_area, const std::string& what,
               const PolygonConfig& config = {}) {
  const Polygon2 hull = ConcaveHull(points, config);
  ASSERT_TRUE(hull.valid) << what;
  EXPECT_NEAR(hull.area, true_area, 0.05 * true_area) << what << " cell " << hull.cell_size;
  EXPECT_NEAR(SignedArea(hull.vertices), hull.area, 1e-12);  // counter-clockwise
  EXPECT_GT(hull.area, 0.0);
  EXPECT_TRUE(IsSimplePolygon(hull.vertices)) << what;
  const auto triangles = TriangulatePolygon(hull.vertices);
  EXPECT_EQ(triangles.size(), hull.vertices.size() - 2);
  EXPECT_NEAR(TriangulatedArea(hull.vertices), hull.area, 1e-9 * hull.area) << what;
  // Simplification keeps the outline small (a rectilinear shape needs few corners).
  EXPECT_LT(hull.vertices.size(), 60u) << what;
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
  const Polygon2 hull = ConcaveHull(SampleRegion(InsideNotch, 3.0, 2.0, 20000, 5));
  ASSERT_TRUE(hull.valid);
  const Eigen::Vector2d notch_centre(1.5, 1.4);
  // Winding test: a ray to +x crosses the outline an even number of times when outside.
  int crossings = 0;
  const auto& v = hull.vertices;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const auto& a = v[i];
    const auto& b = v[(i + 1) % v.size()];
    if ((a.y() > notch_centre.y()) != (b.y() > notch_centre.y())) {
      const double x = a.x() + (notch_centre.y() - a.y()) / (b.y() - a.y()) * (b.x() - a.x());
      if (x > notch_centre.x()) ++crossings;
    }
  }
  EXPECT_EQ(crossings % 2, 0);
}

TEST(ConcaveHull, RotatedLatticeSamplesAndADisk) {
  // Range-image-like regular sampling of a rotated 2 x 1 rectangle with a second, smaller blob that
  // must be dropped (the largest region wins).
  Points points;
  const double angle = 0.5;
  const Eigen::Rotation2Dd R(angle);
  for (double x = 0.0; x <= 2.0; x += 0.01) {
    for (double y = 0.0; y <= 1.0; y += 0.01) points.push_back(R * Eigen::Vector2d(x, y));
  }
  for (double x = 5.0; x <= 5.3; x += 0.01) {
    for (double y = 5.0; y <= 5.3; y += 0.01) points.push_back({x, y});
  }
  CheckHull(points, 2.0, "rotated lattice rectangle");

  Points disk;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  while (disk.size() < 30000) {
    const Eigen::Vector2d p(u(rng), u(rng));
    if (p.squaredNorm() <= 1.0) disk.push_back(p + Eigen::Vector2d(100.0, -50.0));
  }
  const Polygon2 hull = ConcaveHull(disk);
  ASSERT_TRUE(hull.valid);
  EXPECT_NEAR(hull.area, M_PI, 0.05 * M_PI);
  EXPECT_TRUE(IsSimplePolygon(hull.vertices));
}

TEST(ConcaveHull, DeterministicAndDegenerateInputs) {
  const Points points = SampleRegion(InsideL, 4.0, 3.0, 10000, 6);
  const Polygon2 a = ConcaveHull(points);
  const Polygon2 b = ConcaveHull(points);
  EXPECT_EQ(a.vertices, b.vertices);

  EXPECT_FALSE(ConcaveHull({}).valid);
  EXPECT_FALSE(ConcaveHull({{0, 0}, {1, 1}}).valid);
  Points line;
  for (int i = 0; i < 1000; ++i) line.push_back({0.001 * i, 0.002 * i});
  EXPECT_FALSE(ConcaveHull(line).valid);
  Points same(500, Eigen::Vector2d(1, 2));
  EXPECT_FALSE(ConcaveHull(same).valid);
  // Non-finite points are ignored.
  Points with_nan = points;
  with_nan.push_back({std::nan(""), 0.0});
  EXPECT_EQ(ConcaveHull(with_nan).vertices, a.vertices);

  PolygonConfig bad;
  bad.cell_size = -1;
  EXPECT_THROW(ConcaveHull(points, bad), CheckError);
}

TEST(ConcaveHull, ExplicitCellAndNoSimplification) {
  PolygonConfig config;
  config.cell_size = 0.05;
  config.simplify_tolerance = -1.0;  // raw marching squares outline
  const Polygon2 hull = ConcaveHull(SampleRegion(InsideL, 4.0, 3.0, 20000, 8), config);
  ASSERT_TRUE(hull.valid);
  // The cell is stretched per axis to fit the extent (by well under 2% here).
  EXPECT_NEAR(hull.cell_size, 0.05, 0.02 * 0.05);
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

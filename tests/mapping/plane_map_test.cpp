// Global plane map: association, merging, refit under pose changes, outlines, on synthetic rooms
// whose planes, visible regions and poses are known exactly.
#include "planeslam/mapping/plane_map.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <set>

#include "mapping/covered_cells.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::mapping {
namespace {

constexpr double kDeg = M_PI / 180.0;

/// A rectangle o + s a + t b, s in [0, |a|], t in [0, |b|] (a, b orthogonal).
struct Rect {
  Eigen::Vector3d o, a, b;
  Eigen::Vector3d Normal() const { return a.cross(b).normalized(); }
};

/// Grid samples of a rectangle at spacing h (cell centres).
std::vector<Eigen::Vector3d> Sample(const Rect& r, double h) {
  std::vector<Eigen::Vector3d> pts;
  const int na = static_cast<int>(std::round(r.a.norm() / h));
  const int nb = static_cast<int>(std::round(r.b.norm() / h));
  for (int i = 0; i < na; ++i) {
    for (int j = 0; j < nb; ++j) {
      pts.push_back(r.o + ((i + 0.5) / na) * r.a + ((j + 0.5) / nb) * r.b);
    }
  }
  return pts;
}

/// Pinhole-like frustum (Kinect field of view 58 x 45 deg, range 0.5 .. 4 m); sensor z forward.
bool Visible(const Pose& T_world_sensor, const Eigen::Vector3d& p_world) {
  const Eigen::Vector3d p = T_world_sensor.inverse() * p_world;
  if (p.z() < 0.5 || p.norm() > 4.0) return false;
  return std::abs(p.x() / p.z()) < std::tan(29 * kDeg) &&
         std::abs(p.y() / p.z()) < std::tan(22.5 * kDeg);
}

/// A sensor at `position` looking along yaw (about world z) and pitch (down is negative); sensor
/// axes: z forward, x right, y down.
Pose LookPose(const Eigen::Vector3d& position, double yaw, double pitch) {
  const Eigen::Vector3d fwd(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw),
                            std::sin(pitch));
  const Eigen::Vector3d right = fwd.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = fwd.cross(right);
  Pose T = Pose::Identity();
  T.linear().col(0) = right;
  T.linear().col(1) = down;
  T.linear().col(2) = fwd;
  T.translation() = position;
  return T;
}

/// A detected plane made from sensor-frame points the way a detector does (moments, Fit).
detection::Plane MakePlane(int id, const std::vector<Eigen::Vector3f>& pts) {
  detection::Plane plane;
  plane.id = id;
  for (const auto& p : pts) plane.moments.Add(p);
  const detection::PlaneFit fit = plane.moments.Fit();
  plane.normal = fit.normal;
  plane.d = fit.d;
  plane.centroid = fit.centroid;
  plane.point_count = plane.moments.count();
  plane.mse = fit.mse;
  return plane;
}

struct SimFrame {
  std::vector<detection::Plane> planes;
  std::vector<std::vector<Eigen::Vector3f>> points;
  std::vector<int> truth;  ///< index of the world rectangle of each plane
};

/// The parts of `rects` visible from `T` (through `visible`), as sensor-frame planes with noise
/// along each rectangle's normal (sigma [m]). `seen[r][i]` marks sample i of rect r as seen.
template <class VisibleFn>
SimFrame Simulate(const std::vector<Rect>& rects, double h, const Pose& T, VisibleFn visible,
                  double sigma, std::mt19937& rng, std::vector<std::vector<bool>>* seen = nullptr) {
  std::normal_distribution<double> noise(0.0, sigma);
  SimFrame f;
  const Pose T_sensor_world = T.inverse();
  for (std::size_t r = 0; r < rects.size(); ++r) {
    const auto samples = Sample(rects[r], h);
    std::vector<Eigen::Vector3f> pts;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      if (!visible(T, samples[i])) continue;
      if (seen) (*seen)[r][i] = true;
      const Eigen::Vector3d p = samples[i] + noise(rng) * rects[r].Normal();
      pts.push_back((T_sensor_world * p).cast<float>());
    }
    if (pts.size() < 100) continue;
    f.planes.push_back(MakePlane(static_cast<int>(f.planes.size()) + 1, pts));
    f.points.push_back(std::move(pts));
    f.truth.push_back(static_cast<int>(r));
  }
  return f;
}

/// A 6 x 4 x 2.5 m room: floor and four walls.
std::vector<Rect> Room() {
  const double X = 6, Y = 4, Z = 2.5;
  return {
      {{0, 0, 0}, {X, 0, 0}, {0, Y, 0}},  // floor z = 0
      {{0, 0, 0}, {0, Y, 0}, {0, 0, Z}},  // wall x = 0
      {{X, 0, 0}, {0, 0, Z}, {0, Y, 0}},  // wall x = 6
      {{0, 0, 0}, {0, 0, Z}, {X, 0, 0}},  // wall y = 0
      {{0, Y, 0}, {X, 0, 0}, {0, 0, Z}},  // wall y = 4
  };
}

std::vector<Pose> RoomPoses() {
  std::vector<Pose> poses;
  for (int k = 0; k < 8; ++k) {
    const double yaw = k * 45.0 * kDeg;
    poses.push_back(
        LookPose(Eigen::Vector3d(3.0 + 0.3 * std::cos(yaw), 2.0, 1.4), yaw, -25 * kDeg));
  }
  return poses;
}

/// Area of the seen samples of `r` (grid of Sample(r, h)) with the unseen holes filled: everything
/// except the unseen samples 4-connected to the rectangle's border.
double FilledArea(const Rect& r, double h, const std::vector<bool>& seen) {
  const int na = static_cast<int>(std::round(r.a.norm() / h));
  const int nb = static_cast<int>(std::round(r.b.norm() / h));
  return static_cast<double>(test::CoveredCells(seen, na, nb)) * h * h;
}

/// The map plane closest to the infinite plane through `r` (unoriented), and its distance measures.
const MapPlane* Closest(const PlaneMap& map, const Rect& r, double* angle_deg) {
  const MapPlane* best = nullptr;
  double best_angle = 1e9;
  const Eigen::Vector3d n = r.Normal();
  for (const auto& p : map.planes()) {
    const double angle = std::acos(std::min(1.0, std::abs(p.normal.dot(n)))) / kDeg;
    const double offset = std::abs(p.normal.dot(r.o) - p.d);
    if (offset < 0.05 && angle < best_angle) {
      best = &p;
      best_angle = angle;
    }
  }
  *angle_deg = best_angle;
  return best;
}

TEST(PointStats, TransformAndMergeMatchThePointsMoments) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::vector<Eigen::Vector3d> a, b;
  for (int i = 0; i < 200; ++i) a.emplace_back(u(rng) + 100.0, u(rng), 0.1 * u(rng));
  for (int i = 0; i < 150; ++i) b.emplace_back(u(rng), u(rng) - 50.0, u(rng));
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(10, -20, 5);

  detection::PlaneMoments ma, mb, mab_t;
  for (const auto& p : a) ma.Add(p);
  for (const auto& p : b) mb.Add(p);
  for (const auto& p : a) mab_t.Add(Eigen::Vector3d(T * p));
  for (const auto& p : b) mab_t.Add(Eigen::Vector3d(T * p));

  PointStats s = PointStats::FromMoments(ma).Transformed(T);
  s.Merge(PointStats::FromMoments(mb).Transformed(T));
  EXPECT_EQ(s.count, 350);
  EXPECT_LT((s.centroid - mab_t.Centroid()).norm(), 1e-9);
  EXPECT_LT((s.scatter - mab_t.Scatter()).norm(), 1e-8 * mab_t.Scatter().norm());

  // Fit orientation follows the reference direction.
  PointStats flat = PointStats::FromMoments(ma);
  EXPECT_GT(flat.Fit(Eigen::Vector3d::UnitZ()).normal.z(), 0.99);
  EXPECT_LT(flat.Fit(-Eigen::Vector3d::UnitZ()).normal.z(), -0.99);
}

TEST(PlaneMapConfig, ValidateNamesBadValues) {
  EXPECT_TRUE(PlaneMapConfig().Validate().empty());
  PlaneMapConfig c;
  c.max_offset = -1;
  c.sample_cell_size = 0;
  const auto problems = c.Validate();
  ASSERT_EQ(problems.size(), 2u);
  EXPECT_NE(problems[0].find("max_offset"), std::string::npos);
  EXPECT_NE(problems[1].find("sample_cell_size"), std::string::npos);
  EXPECT_THROW(PlaneMap{c}, CheckError);
}

TEST(PlaneMap, RoomPlanesAppearOnceWithAccurateNormalsAndAreas) {
  const auto rects = Room();
  const double h = 0.02;
  std::mt19937 rng(1);
  std::vector<std::vector<bool>> seen(rects.size());
  for (std::size_t r = 0; r < rects.size(); ++r) seen[r].assign(Sample(rects[r], h).size(), false);

  PlaneMap map;
  const auto poses = RoomPoses();
  int created = 0;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const SimFrame f = Simulate(rects, h, poses[k], Visible, 0.005, rng, &seen);
    const FrameAssociation a =
        map.AddObservations(static_cast<std::int64_t>(k), poses[k], f.planes, f.points);
    ASSERT_EQ(a.map_ids.size(), f.planes.size());
    for (int id : a.map_ids) EXPECT_GT(id, 0);
    created += a.created;
  }

  int visible_planes = 0;
  std::set<int> matched_ids;
  for (std::size_t r = 0; r < rects.size(); ++r) {
    const double true_area = std::count(seen[r].begin(), seen[r].end(), true) * h * h;
    if (true_area == 0) continue;
    const double filled_area = FilledArea(rects[r], h, seen[r]);
    ++visible_planes;
    double angle = 0;
    const MapPlane* p = Closest(map, rects[r], &angle);
    ASSERT_NE(p, nullptr) << "rect " << r;
    matched_ids.insert(p->id);
    EXPECT_LT(angle, 1.0) << "rect " << r;
    const MapPlaneOutline outline = map.Outline(*p);
    ASSERT_TRUE(outline.region.valid()) << "rect " << r;
    // The outline has no holes (the floor under the sensors is never seen): compare it with the
    // seen region with its holes filled, and the observed area with the seen area.
    EXPECT_NEAR(outline.region.area, filled_area, 0.15 * filled_area) << "rect " << r;
    EXPECT_NEAR(outline.observed_area, true_area, 0.15 * true_area) << "rect " << r;
    std::printf(
        "rect %zu: seen %.3f m^2 (filled %.3f), outline %.3f, observed %.3f, angle %.3f deg\n", r,
        true_area, filled_area, outline.region.area, outline.observed_area, angle);
    // Outline vertices lie on the map plane.
    for (const auto& part : outline.part_vertices) {
      for (const auto& v : part) EXPECT_NEAR(p->normal.dot(v), p->d, 1e-9);
    }
    // The normal points away from the sensors that saw it.
    for (const auto& obs : p->observations) {
      EXPECT_LT(p->normal.dot(map.KeyframePose(obs.keyframe_id).translation()), p->d);
    }
  }
  EXPECT_EQ(visible_planes, 5);
  EXPECT_EQ(static_cast<int>(map.size()), visible_planes);  // each appears exactly once
  EXPECT_EQ(static_cast<int>(matched_ids.size()), visible_planes);
  EXPECT_EQ(created, visible_planes);
}

/// Sees only the part of a wall with x in [x0, x1].
auto Window(double x0, double x1) {
  return [x0, x1](const Pose&, const Eigen::Vector3d& p) { return p.x() >= x0 && p.x() <= x1; };
}

TEST(PlaneMap, PlaneSeenInTwoSeparateHalvesMergesWhenTheGapIsSeen) {
  const std::vector<Rect> wall = {{{0, 4, 0}, {6, 0, 0}, {0, 0, 2.5}}};
  std::mt19937 rng(2);
  PlaneMap map;
  const Pose T = LookPose(Eigen::Vector3d(3, 1, 1.2), M_PI / 2, 0);
  auto add = [&](std::int64_t kf, double x0, double x1) {
    const SimFrame f = Simulate(wall, 0.02, T, Window(x0, x1), 0.005, rng);
    return map.AddObservations(kf, T, f.planes, f.points);
  };
  EXPECT_EQ(add(0, 0.0, 2.0).created, 1);
  EXPECT_EQ(add(1, 4.0, 6.0).created, 1);  // 2 m apart: not (yet) known to be one surface
  EXPECT_EQ(map.size(), 2u);
  const FrameAssociation mid = add(2, 1.8, 4.2);  // overlaps both
  EXPECT_EQ(mid.merged, 1);
  ASSERT_EQ(map.size(), 1u);
  EXPECT_EQ(map.planes()[0].id, 1);  // the smaller id survives
  EXPECT_EQ(map.ResolveId(2), 1);
  EXPECT_EQ(map.Find(2), &map.planes()[0]);
  EXPECT_EQ(mid.map_ids, std::vector<int>{1});
  EXPECT_EQ(map.planes()[0].observations.size(), 3u);
  EXPECT_EQ(map.planes()[0].first_keyframe, 0);
  EXPECT_EQ(map.planes()[0].last_keyframe, 2);
  const MapPlaneOutline o = map.Outline(map.planes()[0]);
  EXPECT_NEAR(o.region.area, 6.0 * 2.5, 0.15 * 6.0 * 2.5);
}

TEST(PlaneMap, SamplesGrowWithAreaNotWithKeyframes) {
  // The same wall part seen 20 times keeps about one observation's samples; a new part adds.
  const std::vector<Rect> wall = {{{0, 4, 0}, {6, 0, 0}, {0, 0, 2.5}}};
  std::mt19937 rng(8);
  PlaneMap map;
  const Pose T = LookPose(Eigen::Vector3d(3, 1, 1.2), M_PI / 2, 0);
  std::size_t first = 0;
  for (int k = 0; k < 20; ++k) {
    const SimFrame f = Simulate(wall, 0.02, T, Window(0, 3), 0.005, rng);
    map.AddObservations(k, T, f.planes, f.points);
    if (k == 0) first = map.WorldSamples(map.planes()[0]).size();
  }
  ASSERT_EQ(map.size(), 1u);
  EXPECT_EQ(map.planes()[0].observations.size(), 20u);
  EXPECT_LT(map.WorldSamples(map.planes()[0]).size(), first * 13 / 10);
  const SimFrame f = Simulate(wall, 0.02, T, Window(3, 6), 0.005, rng);
  map.AddObservations(20, T, f.planes, f.points);
  EXPECT_GT(map.WorldSamples(map.planes()[0]).size(), first * 18 / 10);
}

TEST(PlaneMap, DistantPlanesMergeAsPartsOfOnePlaneWithinTheOffsetAskedFor) {
  // Two table tops 3 m apart, at heights 0.70 and 0.73 m, seen by two keyframes.
  const std::vector<Rect> rects = {
      {{0, 0, 0.70}, {1, 0, 0}, {0, 1, 0}},
      {{4, 0, 0.73}, {1, 0, 0}, {0, 1, 0}},
  };
  std::mt19937 rng(3);
  PlaneMap map;
  const Pose T_top = LookPose(Eigen::Vector3d(2.5, 0.5, 2.5), 0, -M_PI / 2 + 0.01);
  const SimFrame f1 = Simulate(
      rects, 0.02, T_top, [](const Pose&, const Eigen::Vector3d& p) { return p.x() < 2; }, 0.003,
      rng);
  map.AddObservations(0, T_top, f1.planes, f1.points);
  const SimFrame f2 = Simulate(
      rects, 0.02, T_top, [](const Pose&, const Eigen::Vector3d& p) { return p.x() > 2; }, 0.003,
      rng);
  // Association is local: the second top does not join the first one's map plane.
  EXPECT_EQ(map.AddObservations(1, T_top, f2.planes, f2.points).created, 1);
  ASSERT_EQ(map.size(), 2u);
  EXPECT_EQ(map.MergeCoincidentPlanes(), 0);      // they do not touch
  EXPECT_EQ(map.MergeCoincidentPlanes(0.02), 0);  // 3 cm apart: two surfaces (SLAM's default)
  // Within 5 cm (the finished map's default): one plane between the two, two outline parts.
  EXPECT_EQ(map.MergeCoincidentPlanes(0.05), 1);
  ASSERT_EQ(map.size(), 1u);
  EXPECT_NEAR(map.planes()[0].centroid.z(), 0.715, 0.005);
  EXPECT_GT(std::abs(map.planes()[0].normal.z()), std::cos(1.0 * M_PI / 180));
  const MapPlaneOutline outline = map.Outline(map.planes()[0]);
  ASSERT_EQ(outline.region.parts.size(), 2u);
  for (const Polygon2& part : outline.region.parts) EXPECT_NEAR(part.area, 1.0, 0.15);
  ASSERT_EQ(outline.part_vertices.size(), 2u);
  const double x0 = outline.part_vertices[0].front().x();
  const double x1 = outline.part_vertices[1].front().x();
  EXPECT_GT(std::max(x0, x1) - std::min(x0, x1), 2.5);  // one part per table
}

TEST(PlaneMap, TheTwoFacesOfAPartitionStayApart) {
  std::mt19937 rng(3);
  PlaneMap faces;
  const std::vector<Rect> a = {{{0, 2.0, 0}, {3, 0, 0}, {0, 0, 2}}};
  const std::vector<Rect> b = {{{0, 2.02, 0}, {3, 0, 0}, {0, 0, 2}}};
  const Pose front = LookPose(Eigen::Vector3d(1.5, 0, 1), M_PI / 2, 0);
  const Pose back = LookPose(Eigen::Vector3d(1.5, 4, 1), -M_PI / 2, 0);
  auto all = [](const Pose&, const Eigen::Vector3d&) { return true; };
  const SimFrame fa = Simulate(a, 0.02, front, all, 0.002, rng);
  const SimFrame fb = Simulate(b, 0.02, back, all, 0.002, rng);
  faces.AddObservations(0, front, fa.planes, fa.points);
  faces.AddObservations(1, back, fb.planes, fb.points);
  ASSERT_EQ(faces.size(), 2u);
  EXPECT_LT(faces.planes()[0].normal.dot(faces.planes()[1].normal), -0.99);
}

TEST(PlaneMap, RefitAfterRigidMotionOfAllPosesMovesEveryPlaneExactly) {
  const auto rects = Room();
  std::mt19937 rng(4);
  PlaneMap map;
  const auto poses = RoomPoses();
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const SimFrame f = Simulate(rects, 0.03, poses[k], Visible, 0.005, rng);
    map.AddObservations(static_cast<std::int64_t>(k), poses[k], f.planes, f.points);
  }
  const std::vector<MapPlane> before = map.planes();
  ASSERT_GE(before.size(), 5u);

  Pose G = Pose::Identity();
  G.linear() = Eigen::AngleAxisd(2.1, Eigen::Vector3d(-1, 0.5, 2).normalized()).toRotationMatrix();
  G.translation() = Eigen::Vector3d(-7.5, 3.25, 12.0);
  std::unordered_map<std::int64_t, Pose> moved;
  for (std::size_t k = 0; k < poses.size(); ++k) moved[static_cast<std::int64_t>(k)] = G * poses[k];
  EXPECT_EQ(map.Refit(moved), 0);

  ASSERT_EQ(map.size(), before.size());
  for (std::size_t i = 0; i < before.size(); ++i) {
    const MapPlane& b = before[i];
    const MapPlane& a = map.planes()[i];
    EXPECT_EQ(a.id, b.id);
    EXPECT_EQ(a.point_count(), b.point_count());
    const Eigen::Vector3d n = G.linear() * b.normal;
    EXPECT_LT((a.normal - n).norm(), 1e-9);
    EXPECT_NEAR(a.d, b.d + n.dot(G.translation()), 1e-9);  // d_a = d_b + n_a . t
    EXPECT_LT((a.centroid - G * b.centroid).norm(), 1e-9);
    EXPECT_NEAR(a.mse, b.mse, 1e-12);
  }
  // Moving back restores the original map.
  std::unordered_map<std::int64_t, Pose> original;
  for (std::size_t k = 0; k < poses.size(); ++k) original[static_cast<std::int64_t>(k)] = poses[k];
  map.Refit(original);
  for (std::size_t i = 0; i < before.size(); ++i) {
    EXPECT_LT((map.planes()[i].normal - before[i].normal).norm(), 1e-9);
    EXPECT_NEAR(map.planes()[i].d, before[i].d, 1e-9);
  }
}

TEST(PlaneMap, RefitWithCorrectedPosesMergesDuplicatesFromDrift) {
  // The second half of the frames carries 0.25 m of drift along the wall normal: the wall is mapped
  // twice. A loop closure's corrected poses make the copies coincide and Refit merges them.
  const std::vector<Rect> wall = {{{0, 4, 0}, {6, 0, 0}, {0, 0, 2.5}}};
  std::mt19937 rng(5);
  PlaneMap map;
  std::unordered_map<std::int64_t, Pose> truth;
  for (int k = 0; k < 6; ++k) {
    const Pose T = LookPose(Eigen::Vector3d(0.5 + k, 1.5, 1.2), M_PI / 2, 0);
    Pose reported = T;
    if (k >= 3) reported.translation() += Eigen::Vector3d(0, 0.25, 0);
    const SimFrame f = Simulate(wall, 0.02, T, Visible, 0.005, rng);
    map.AddObservations(k, reported, f.planes, f.points);
    truth[k] = T;
  }
  ASSERT_EQ(map.size(), 2u);
  EXPECT_EQ(map.Refit(truth), 1);
  ASSERT_EQ(map.size(), 1u);
  EXPECT_NEAR(std::abs(map.planes()[0].d), 4.0, 0.01);
  EXPECT_EQ(map.planes()[0].observations.size(), 6u);
}

TEST(PlaneMap, SameInputGivesTheSameMap) {
  const auto rects = Room();
  const auto poses = RoomPoses();
  std::vector<MapPlaneOutline> outlines[2];
  std::vector<MapPlane> planes[2];
  for (int run = 0; run < 2; ++run) {
    std::mt19937 rng(11);
    PlaneMap map;
    for (std::size_t k = 0; k < poses.size(); ++k) {
      const SimFrame f = Simulate(rects, 0.03, poses[k], Visible, 0.005, rng);
      map.AddObservations(static_cast<std::int64_t>(k), poses[k], f.planes, f.points);
    }
    planes[run] = map.planes();
    outlines[run] = map.Outlines();
  }
  ASSERT_EQ(planes[0].size(), planes[1].size());
  for (std::size_t i = 0; i < planes[0].size(); ++i) {
    EXPECT_EQ(planes[0][i].id, planes[1][i].id);
    EXPECT_EQ(planes[0][i].normal, planes[1][i].normal);  // bit-identical
    EXPECT_EQ(planes[0][i].d, planes[1][i].d);
    EXPECT_EQ(outlines[0][i].part_vertices, outlines[1][i].part_vertices);
  }
}

TEST(PlaneMap, AddFrameTakesPointsFromTheLabelImage) {
  // An 80 x 60 cloud: left half on the plane z = 2, right half on z = 3 (two labels), an invalid
  // pixel in each.
  datasets::OrganizedCloud cloud(80, 60);
  detection::Segmentation seg;
  seg.width = 80;
  seg.height = 60;
  seg.labels.assign(cloud.size(), -1);
  std::vector<std::vector<Eigen::Vector3f>> pts(2);
  for (int r = 0; r < 60; ++r) {
    for (int c = 0; c < 80; ++c) {
      const int label = c < 40 ? 1 : 2;
      const float z = label == 1 ? 2.0f : 3.0f;
      seg.labels[static_cast<std::size_t>(r) * 80 + c] = label;
      if (r == 7 && (c == 3 || c == 50)) continue;  // NaN: must be ignored
      cloud.at(r, c) = Eigen::Vector3f((c - 40) * 0.01f * z, (r - 30) * 0.01f * z, z);
      pts[label - 1].push_back(cloud.at(r, c));
    }
  }
  seg.planes = {MakePlane(1, pts[0]), MakePlane(2, pts[1])};
  PlaneMapConfig config;
  config.sample_pixel_stride = 1;  // every pixel (the test's 2 cm spacing against 4 cm cells)
  PlaneMap map(config);
  const FrameAssociation a = map.AddFrame(0, Pose::Identity(), seg, cloud);
  EXPECT_EQ(a.created, 2);
  ASSERT_EQ(map.size(), 2u);
  EXPECT_NEAR(map.planes()[0].d, 2.0, 1e-6);
  EXPECT_NEAR(map.planes()[1].d, 3.0, 1e-6);
  // Samples: one per 4 cm cell of the 0.8 x 1.2 m (z = 2, 2 cm spacing) patch -> about 20 x 30.
  EXPECT_NEAR(static_cast<double>(map.planes()[0].observations[0].samples_sensor.size()), 600, 60);
  EXPECT_EQ(map.planes()[0].observations[0].detection_id, 1);
}

TEST(PlaneMap, PlanesWithoutPointsUseTheirSecondMomentsAsExtent) {
  // Same wall, two frames, no points given: the rectangle from the moments still lets the second
  // observation (overlapping) associate.
  const std::vector<Rect> wall = {{{0, 4, 0}, {6, 0, 0}, {0, 0, 2.5}}};
  std::mt19937 rng(6);
  PlaneMap map;
  const Pose T = LookPose(Eigen::Vector3d(3, 1, 1.2), M_PI / 2, 0);
  const SimFrame f1 = Simulate(wall, 0.02, T, Window(0, 3.5), 0.005, rng);
  const SimFrame f2 = Simulate(wall, 0.02, T, Window(3, 6), 0.005, rng);
  map.AddObservations(0, T, f1.planes, {});
  map.AddObservations(1, T, f2.planes, {});
  ASSERT_EQ(map.size(), 1u);
  // The uniform-rectangle extent has the true size: outline area near 6 x 2.5.
  EXPECT_NEAR(map.Outline(map.planes()[0]).region.area, 15.0, 0.15 * 15.0);
}

TEST(PlaneMap, SmallPlanesAreSkippedAndKeyframePosesAreChecked) {
  PlaneMap map;
  std::vector<Eigen::Vector3f> pts;
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) pts.emplace_back(0.01f * i, 0.01f * j, 1.0f);
  }
  const FrameAssociation a = map.AddObservations(0, Pose::Identity(), {MakePlane(1, pts)}, {pts});
  EXPECT_EQ(a.map_ids, std::vector<int>{-1});
  EXPECT_EQ(map.size(), 0u);
  Pose other = Pose::Identity();
  other.translation().x() = 1.0;
  EXPECT_THROW(map.AddObservations(0, other, {}, {}), CheckError);
  EXPECT_THROW(map.KeyframePose(42), CheckError);
}

}  // namespace
}  // namespace planeslam::mapping

// Alignment of a scan's structure to the local voxel map along the directions the planes leave
// open: a corridor and a single wall with random clutter, moved along the open directions.
#include "planeslam/registration/local_map.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <random>

#include "registration/corridor_scene.hpp"

namespace planeslam::registration {
namespace {

using test::AddBox;
using test::CorridorPlanesInCamera;
using test::LookAlongX;
using test::MakeCorridor;
using test::RayCast;
using test::SmallCamera;

/// `boxes` random boxes (0.1 to 0.5 m a side) against the corridor's walls, floor or ceiling,
/// between 1.5 and 7 m ahead.
void AddClutter(int boxes, std::mt19937& rng, datasets::SyntheticScene* scene) {
  std::uniform_real_distribution<double> along(1.5, 7.0), size(0.1, 0.5), side(0.0, 1.0);
  for (int i = 0; i < boxes; ++i) {
    const double x = along(rng), sx = size(rng), sy = size(rng), sz = size(rng);
    Eigen::Vector3d lo, hi;
    if (side(rng) < 0.5) {  // against a wall
      const bool left = side(rng) < 0.5;
      const double z = -1.2 + side(rng) * (2.5 - sz);
      lo << x, left ? 1.0 - sy : -1.0, z;
      hi << x + sx, left ? 1.0 : -1.0 + sy, z + sz;
    } else {  // on the floor
      const double y = -1.0 + side(rng) * (2.0 - sy);
      lo << x, y, -1.2;
      hi << x + sx, y + sy, -1.2 + sz;
    }
    AddBox(lo, hi, *scene);
  }
}

/// The previous scan's structure as the local map (at T_world_prev) and the current scan's as
/// the alignment's source, both thinned to half a voxel of a hundredth of the previous reach.
struct ScanPair {
  ScanPair(const datasets::OrganizedCloud& prev, const datasets::OrganizedCloud& curr,
           const Pose& T_world_prev)
      : voxel(ScanReach(prev) / 100.0), map(voxel, LocalMapConfig().max_points_per_voxel) {
    map.Insert(ShapePoints(VoxelDownsample(StructurePoints(prev, nullptr), 0.5 * voxel), voxel),
               T_world_prev, ScanReach(prev));
    source = ShapePoints(VoxelDownsample(StructurePoints(curr, nullptr), 0.5 * voxel), voxel);
  }
  double voxel;
  LocalVoxelMap map;
  std::vector<ShapedPoint> source;
};

/// Planes of the corridor registered between two views: the axis is left open.
RegistrationResult CorridorRegistration(const test::CorridorScene& scene, const Pose& T_world_prev,
                                        const Pose& T_world_curr, const MotionPrior& prior) {
  const auto prev = CorridorPlanesInCamera(scene, T_world_prev);
  const auto curr = CorridorPlanesInCamera(scene, T_world_curr);
  std::vector<PlaneMatch> matches;
  for (int i = 0; i < 4; ++i) matches.push_back({i, i, false});
  return RegisterPlanes(prev, curr, matches, prior);
}

TEST(LocalMap, RecoversCorridorAxisFromClutterOverRandomDraws) {
  std::mt19937 rng(33);
  const datasets::PinholeIntrinsics k = SmallCamera();
  std::uniform_real_distribution<double> step(0.05, 0.3), prior_error(-0.03, 0.03), small(-1, 1);
  int failures = 0;
  const int draws = 20;
  for (int draw = 0; draw < draws; ++draw) {
    test::CorridorScene scene = MakeCorridor(false);
    AddClutter(6, rng, &scene.scene);
    Pose T_world_prev = Pose::Identity();
    T_world_prev.linear() = LookAlongX() * ExpSO3(0.02 * Eigen::Vector3d(small(rng), small(rng),
                                                                           small(rng)));
    T_world_prev.translation() << 0.0, 0.2 * small(rng), 0.1 * small(rng);
    Pose T_prev_curr = Pose::Identity();
    T_prev_curr.linear() = ExpSO3(0.01 * Eigen::Vector3d(small(rng), small(rng), small(rng)));
    const Eigen::Vector3d axis = T_world_prev.linear().transpose() * Eigen::Vector3d::UnitX();
    T_prev_curr.translation() = step(rng) * axis + Eigen::Vector3d(0.02, -0.02, 0.0);
    const Pose T_world_curr = T_world_prev * T_prev_curr;
    const datasets::OrganizedCloud prev = RayCast(scene, k, T_world_prev, 0.002, rng);
    const datasets::OrganizedCloud curr = RayCast(scene, k, T_world_curr, 0.002, rng);

    MotionPrior prior;
    prior.T_prev_curr = T_prev_curr;
    prior.T_prev_curr.translation() += prior_error(rng) * axis;
    prior.covariance = (Vector6d() << 0.1, 0.1, 0.1, 0.05, 0.05, 0.05)
                           .finished().array().square().matrix().asDiagonal();
    RegistrationResult reg = CorridorRegistration(scene, T_world_prev, T_world_curr, prior);
    ASSERT_TRUE(reg.degenerate);

    LocalMapConfig config;
    const ScanPair pair(prev, curr, T_world_prev);
    const bool used = FillDegenerateFromLocalMap(pair.map, T_world_prev, pair.source, config, &reg);
    const double error =
        (reg.T_prev_curr.translation() - T_prev_curr.translation()).dot(axis);
    if (!used || std::abs(error) > 0.003) ++failures;
    if (used) {
      // Filled again (as after a complete outline filled the axis first): nothing is left to
      // the prior, and its count of translations does not go below zero (the velocity model
      // holds the rotation when more directions than translations are left to the prior).
      FillDegenerateFromLocalMap(pair.map, T_world_prev, pair.source, config, &reg);
      EXPECT_EQ(reg.prior_directions, 0);
      EXPECT_EQ(reg.prior_translations, 0);
    }
  }
  EXPECT_LE(failures, 1) << "of " << draws << " draws";  // budget: one draw in twenty
}

// The alignment searches its pairs again as the pose moves (beyond 3 % of a voxel): started a
// voxel and a degree off, it reaches the true motion; with the pairs of its first search alone,
// three of these ten draws end millimetres to centimetres off.
TEST(LocalMap, AlignmentConvergesFromAnOffsetBeyondOnePairSearch) {
  std::mt19937 rng(35);
  const datasets::PinholeIntrinsics k = SmallCamera();
  std::uniform_real_distribution<double> small(-1, 1);
  int failures = 0;
  const int draws = 10;
  for (int draw = 0; draw < draws; ++draw) {
    test::CorridorScene scene = MakeCorridor(false);
    AddClutter(6, rng, &scene.scene);
    Pose T_world_prev = Pose::Identity();
    T_world_prev.linear() = LookAlongX();
    Pose T_prev_curr = Pose::Identity();
    T_prev_curr.linear() = ExpSO3(0.01 * Eigen::Vector3d(small(rng), small(rng), small(rng)));
    T_prev_curr.translation() << 0.05 * small(rng), 0.05 * small(rng), 0.2;
    const datasets::OrganizedCloud prev = RayCast(scene, k, T_world_prev, 0.002, rng);
    const datasets::OrganizedCloud curr = RayCast(scene, k, T_world_prev * T_prev_curr, 0.002, rng);

    LocalMapConfig config;
    const ScanPair pair(prev, curr, T_world_prev);
    Pose T_init = T_prev_curr;
    T_init.translation() +=
        1.0 * pair.voxel * Eigen::Vector3d(small(rng), small(rng), small(rng)).normalized();
    T_init.linear() =
        T_init.linear() *
        ExpSO3(0.0175 * Eigen::Vector3d(small(rng), small(rng), small(rng)).normalized());
    const Matrix6d weak = (Vector6d() << 1.0, 1.0, 1.0, 0.25, 0.25, 0.25).finished().asDiagonal();
    const MapAlignmentResult a = AlignToLocalMap(pair.map, T_world_prev, pair.source, T_init,
                                                 Matrix6d::Identity(), weak, config);
    const Pose error = T_prev_curr.inverse() * a.T_prev_curr;
    if (!a.valid || error.translation().norm() > 0.003 ||
        Eigen::AngleAxisd(error.linear()).angle() > 0.1 * M_PI / 180.0) {
      ++failures;
    }
  }
  EXPECT_LE(failures, 1) << "of " << draws << " draws";  // budget: one draw in ten
}

// A second, independent scene: a rotating scanner (spherical range image) beside a single wall
// over the ground, random boxes on the ground and against the wall. Ground and wall leave the
// motion along the wall open; the boxes' points (the scanner's labels say which pixels are the
// ground and the wall) must recover it against the map of the previous scan.
/// A coarse rotating scanner looking down on a street: 0.4 x 0.5 deg, 2 cm range noise.
datasets::SphericalSimConfig StreetScanner() {
  datasets::SphericalSimConfig lidar;
  lidar.azimuth_resolution_deg = 0.4;
  lidar.elevation_min_deg = -25.0;
  lidar.elevation_max_deg = 5.0;
  lidar.elevation_resolution_deg = 0.5;
  lidar.max_range = 40.0;
  lidar.range_sigma = 0.02;
  return lidar;
}

TEST(LocalMap, RecoversMotionAlongASingleWallFromALidarScan) {
  std::mt19937 rng(34);
  std::uniform_real_distribution<double> step(0.3, 1.0), prior_error(-0.1, 0.1), unit(0.0, 1.0);
  const datasets::SphericalSimConfig lidar = StreetScanner();
  int failures = 0;
  const int draws = 8;
  for (int draw = 0; draw < draws; ++draw) {
    // Ground z = 0, wall y = 4; the scanner 1.7 m up, driving along +x.
    std::vector<planeslam::test::GtPlane> big = {{Eigen::Vector3d::UnitZ(), 0.0},
                                                 {-Eigen::Vector3d::UnitY(), -4.0}};
    datasets::SyntheticScene scene = planeslam::test::SceneOf(big);
    for (int i = 0; i < 12; ++i) {
      const double x = -20.0 + 40.0 * unit(rng), size = 0.3 + 0.7 * unit(rng);
      const bool on_wall = unit(rng) < 0.5;
      const double y = on_wall ? 4.0 - size : -6.0 + 8.0 * unit(rng);
      AddBox({x, y, 0.0}, {x + size, y + size, size * (1.0 + unit(rng))}, scene);
    }
    Pose T_world_prev = Pose::Identity();
    T_world_prev.translation() << 0.0, 0.0, 1.7;
    Pose T_prev_curr = Pose::Identity();
    T_prev_curr.translation() << step(rng), 0.05 * (unit(rng) - 0.5), 0.0;
    T_prev_curr.linear() = ExpSO3(Eigen::Vector3d(0.0, 0.0, 0.02 * (unit(rng) - 0.5)));
    const Pose T_world_curr = T_world_prev * T_prev_curr;
    const auto sensor = datasets::MakeSphericalSensor(scene, lidar);
    const datasets::SyntheticRender prev = sensor->Render(T_world_prev, 2 * draw + 1);
    const datasets::SyntheticRender curr = sensor->Render(T_world_curr, 2 * draw + 2);
    // Labels: the ground and the wall (scene planes 1 and 2) are "planes", the rest structure.
    auto labels_of = [](const datasets::SyntheticRender& r) {
      std::vector<std::int32_t> labels(r.cloud.points.size(), -1);
      for (std::size_t i = 0; i < labels.size(); ++i) {
        const int id = r.labels.data[i];
        if (id == 1 || id == 2) labels[i] = id;
      }
      return labels;
    };
    const std::vector<std::int32_t> prev_labels = labels_of(prev), curr_labels = labels_of(curr);

    std::vector<detection::Plane> prev_planes, curr_planes;
    for (const auto& g : big) {
      for (auto [T, out] : {std::pair{T_world_prev, &prev_planes}, {T_world_curr, &curr_planes}}) {
        out->push_back(test::MakePlane(T.linear().transpose() * g.normal,
                                 g.d - g.normal.dot(T.translation())));
      }
    }
    MotionPrior prior;
    prior.T_prev_curr = T_prev_curr;
    prior.T_prev_curr.translation().x() += prior_error(rng);
    prior.covariance = (Vector6d() << 0.3, 0.3, 0.3, 0.05, 0.05, 0.05)
                           .finished().array().square().matrix().asDiagonal();
    RegistrationResult reg =
        RegisterPlanes(prev_planes, curr_planes, {{0, 0, false}, {1, 1, false}}, prior);
    ASSERT_TRUE(reg.degenerate);
    ASSERT_EQ(ConstraintSource(reg), "planes+prior");

    const double voxel = ScanReach(prev.cloud) / 100.0;
    LocalVoxelMap map(voxel, LocalMapConfig().max_points_per_voxel);
    map.Insert(ScanStructure(prev.cloud, &prev_labels, voxel), T_world_prev,
               ScanReach(prev.cloud));
    const bool used = FillDegenerateFromLocalMap(
        map, T_world_prev, ScanStructure(curr.cloud, &curr_labels, voxel), {}, &reg);
    const double error = (reg.T_prev_curr.translation() - T_prev_curr.translation()).x();
    if (!used || reg.prior_translations > 0 || std::abs(error) > 0.03) ++failures;
    if (used) {
      EXPECT_EQ(ConstraintSource(reg), "planes+points");
    }
  }
  EXPECT_LE(failures, 1) << "of " << draws << " draws";  // budget: one draw in eight
}

TEST(LocalMap, ShapesAgreeWithAnIterativeEigensolverOverRandomNeighbourhoods) {
  // Random surfaces (noisy discs), edges (noisy segments spanning rows and columns) and blobs at
  // random orientations and far from the origin: each point's shape against the projector built
  // from Eigen's iterative solver on the same neighbours. Budget: no disagreement in 600 draws.
  std::mt19937 rng(23);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double radius = 0.5;
  int surfaces = 0, edges = 0, blobs = 0;
  for (int draw = 0; draw < 600; ++draw) {
    const Eigen::Matrix3d R =
        Eigen::Quaterniond(gauss(rng), gauss(rng), gauss(rng), gauss(rng)).normalized()
            .toRotationMatrix();
    const Eigen::Vector3d origin(40.0 * gauss(rng), 40.0 * gauss(rng), 5.0 * gauss(rng));
    const int kind = draw % 3;
    std::vector<ScanPoint> points;
    for (int i = 0; i < 40; ++i) {
      Eigen::Vector3d local(0.2 * gauss(rng), 0.2 * gauss(rng), 0.2 * gauss(rng));
      if (kind == 0) local.z() *= 0.02;                    // surface
      if (kind == 1) local.tail<2>() *= 0.02;              // edge along x
      points.push_back({origin + R * local, i % 7, i / 7});  // rows and columns vary
    }
    const std::vector<ShapedPoint> shaped = ShapePoints(points, radius);
    std::size_t next = 0;
    for (const ScanPoint& p : points) {
      std::vector<const ScanPoint*> near;
      for (const ScanPoint& q : points) {
        if ((q.position - p.position).squaredNorm() <= radius * radius) near.push_back(&q);
      }
      Eigen::Matrix3d expected = Eigen::Matrix3d::Zero();
      if (near.size() >= 5) {
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        bool rows = false, cols = false;
        for (const ScanPoint* q : near) {
          mean += q->position / static_cast<double>(near.size());
          rows = rows || q->row != p.row;
          cols = cols || q->col != p.col;
        }
        Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
        for (const ScanPoint* q : near) {
          scatter += (q->position - mean) * (q->position - mean).transpose();
        }
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(scatter);
        for (int k = 0; k < 2; ++k) {
          if (es.eigenvalues()(k) < es.eigenvalues()(2) / 9.0) {
            expected += es.eigenvectors().col(k) * es.eigenvectors().col(k).transpose();
          }
        }
        if (expected.trace() > 1.5 && !(rows && cols)) expected.setZero();
      }
      if (expected.isZero()) {
        ++blobs;
        ASSERT_TRUE(next >= shaped.size() || shaped[next].position != p.position) << draw;
        continue;
      }
      ASSERT_LT(next, shaped.size()) << draw;
      ASSERT_EQ(shaped[next].position, p.position) << draw;
      EXPECT_LT((shaped[next].shape - expected).norm(), 1e-9) << draw;
      (expected.trace() > 1.5 ? edges : surfaces) += 1;
      ++next;
    }
    EXPECT_EQ(next, shaped.size()) << draw;
  }
  EXPECT_GT(surfaces, 1000);
  EXPECT_GT(edges, 1000);
  EXPECT_GT(blobs, 1000);
}

TEST(LocalMap, CompactShapedPointsKeepPositionsAndShapes) {
  // A street-like scan (ground, a wall, boxes as clutter): surfaces and edges both occur.
  std::mt19937 rng(35);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  datasets::SyntheticScene scene = planeslam::test::SceneOf(
      {{Eigen::Vector3d::UnitZ(), 0.0}, {-Eigen::Vector3d::UnitY(), -4.0}});
  for (int i = 0; i < 12; ++i) {
    const double x = -20.0 + 40.0 * unit(rng), y = -6.0 + 8.0 * unit(rng);
    const double size = 0.3 + 0.7 * unit(rng);
    AddBox({x, y, 0.0}, {x + size, y + size, 2.0 * size}, scene);
  }
  const datasets::SphericalSimConfig lidar = StreetScanner();
  Pose T_world_sensor = Pose::Identity();
  T_world_sensor.translation() << 0.0, 0.0, 1.7;
  const datasets::SyntheticRender render =
      datasets::MakeSphericalSensor(scene, lidar)->Render(T_world_sensor, 1);
  const std::vector<ShapedPoint> points =
      ScanStructure(render.cloud, nullptr, ScanReach(render.cloud) / 100.0);
  ASSERT_GT(points.size(), 100u);
  const std::vector<ShapedPoint> back = ExpandShapedPoints(CompactShapedPoints(points));
  ASSERT_EQ(back.size(), points.size());
  int surfaces = 0, edges = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const double trace = points[i].shape.trace();
    (trace > 1.5 ? edges : surfaces) += 1;
    // Float positions: a few micrometres at tens of metres; shapes to float precision.
    EXPECT_LT((back[i].position - points[i].position).norm(), 1e-5) << i;
    EXPECT_LT((back[i].shape - points[i].shape).norm(), 1e-6) << i;
  }
  EXPECT_GT(surfaces, 0);
  EXPECT_GT(edges, 0);
  EXPECT_LE(sizeof(CompactShapedPoint), 28u);
}

}  // namespace
}  // namespace planeslam::registration

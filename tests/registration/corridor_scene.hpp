#pragma once
// A corridor for the registration tests, rendered by the simulation library (datasets/sim): two
// walls, floor and ceiling along world X, no end wall, optionally a cabinet and a pillar that give
// structure along the axis. The camera sees 8 m far; beyond, no return (no visible end).
#include <Eigen/Geometry>
#include <random>
#include <vector>

#include "detection/synthetic_scene.hpp"
#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/synthetic_sensor.hpp"
#include "registration/registration_test_util.hpp"

namespace planeslam::registration::test {

struct CorridorScene {
  std::vector<std::pair<Eigen::Vector3d, double>> planes;  ///< the corridor's planes, world n.p = k
  datasets::SyntheticScene scene;                          ///< the planes and the boxes
  double max_range = 8.0;                                  ///< [m]
};

/// Adds the six faces of the axis-aligned box [lo, hi] (outward normals) to `scene`.
inline void AddBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                   datasets::SyntheticScene& scene) {
  for (int axis = 0; axis < 3; ++axis) {
    for (const double side : {-1.0, 1.0}) {
      datasets::ScenePlane face;
      face.id = static_cast<int>(scene.planes.size()) + 1;
      face.name = "box";
      face.normal = side * Eigen::Vector3d::Unit(axis);
      const double at = side < 0 ? lo(axis) : hi(axis);
      face.d = side * at;
      Eigen::Vector3d flo = lo, fhi = hi;
      flo(axis) = at - 1e-9;
      fhi(axis) = at + 1e-9;
      face.polygons.push_back(planeslam::test::PlaneInBox(face.normal, face.d, flo, fhi));
      scene.planes.push_back(face);
    }
  }
}

inline CorridorScene MakeCorridor(bool with_features) {
  CorridorScene s;
  s.planes = {{Eigen::Vector3d::UnitY(), 1.0},
              {Eigen::Vector3d::UnitY(), -1.0},
              {Eigen::Vector3d::UnitZ(), -1.2},
              {Eigen::Vector3d::UnitZ(), 1.3}};
  std::vector<planeslam::test::GtPlane> planes;
  for (const auto& [n, k] : s.planes) planes.push_back({n, k});
  s.scene = planeslam::test::SceneOf(planes);
  if (with_features) {
    AddBox({3.0, 0.6, -1.2}, {3.6, 1.0, -0.2}, s.scene);    // cabinet on the left wall
    AddBox({5.0, -1.0, -1.2}, {5.25, -0.7, 1.3}, s.scene);  // pillar / door frame
  }
  return s;
}

inline datasets::PinholeIntrinsics SmallCamera() {
  datasets::PinholeIntrinsics k;
  k.width = 160;
  k.height = 120;
  k.fx = 120.0;
  k.fy = 121.0;
  k.cx = 79.3;
  k.cy = 59.6;
  return k;
}

/// R_world_cam of a camera (x right, y down, z forward) looking along world +X with world +Z up.
inline Eigen::Matrix3d LookAlongX() {
  Eigen::Matrix3d r;
  r.col(0) = -Eigen::Vector3d::UnitY();
  r.col(1) = -Eigen::Vector3d::UnitZ();
  r.col(2) = Eigen::Vector3d::UnitX();
  return r;
}

/// Organized cloud seen by a camera at T_world_cam, with Gaussian depth noise `sigma` [m] drawn
/// from `rng` pixel by pixel in row-major order.
inline datasets::OrganizedCloud RayCast(const CorridorScene& s,
                                        const datasets::PinholeIntrinsics& k,
                                        const Pose& T_world_cam, double sigma, std::mt19937& rng) {
  datasets::PinholeSimConfig config;
  config.intrinsics = k;
  config.max_depth = s.max_range;
  config.min_depth = 0.0;
  config.noise = false;
  config.max_incidence_deg = 90.0;
  config.edge_dropout = false;
  datasets::OrganizedCloud cloud =
      datasets::MakePinholeSensor(s.scene, config)->Render(T_world_cam, 0).cloud;
  if (sigma == 0.0) return cloud;
  std::normal_distribution<double> g(0.0, 1.0);
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    if (!cloud.IsValid(i)) continue;
    const Eigen::Vector3d p = cloud.points[i].cast<double>();
    cloud.points[i] = (p * ((p.z() + sigma * g(rng)) / p.z())).cast<float>();
  }
  return cloud;
}

/// The corridor's four planes expressed in the camera at T_world_cam (noise-free, d >= 0).
inline std::vector<detection::Plane> CorridorPlanesInCamera(const CorridorScene& s,
                                                            const Pose& T_world_cam) {
  std::vector<detection::Plane> out;
  for (const auto& [n, off] : s.planes) {
    // n.(R p + o) = k  ->  (R^T n).p = k - n.o
    out.push_back(
        MakePlane(T_world_cam.linear().transpose() * n, off - n.dot(T_world_cam.translation())));
  }
  return out;
}

}  // namespace planeslam::registration::test

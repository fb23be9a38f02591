#pragma once
// A ray-cast corridor for the registration tests: two walls, floor and ceiling along world X, no
// end wall, optionally a cabinet and a pillar that give structure along the axis.
#include <Eigen/Geometry>
#include <random>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "registration/registration_test_util.hpp"

namespace planeslam::registration::test {

struct Box {
  Eigen::Vector3d lo, hi;
};

struct CorridorScene {
  std::vector<std::pair<Eigen::Vector3d, double>> planes;  ///< world n.p = k
  std::vector<Box> boxes;
  double max_range = 8.0;  ///< [m], beyond: no return (the corridor has no visible end)
};

inline CorridorScene MakeCorridor(bool with_features) {
  CorridorScene s;
  s.planes = {{Eigen::Vector3d::UnitY(), 1.0},
              {Eigen::Vector3d::UnitY(), -1.0},
              {Eigen::Vector3d::UnitZ(), -1.2},
              {Eigen::Vector3d::UnitZ(), 1.3}};
  if (with_features) {
    s.boxes.push_back({{3.0, 0.6, -1.2}, {3.6, 1.0, -0.2}});    // cabinet on the left wall
    s.boxes.push_back({{5.0, -1.0, -1.2}, {5.25, -0.7, 1.3}});  // pillar / door frame
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

inline bool RayBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Box& b, double* t) {
  double tmin = 0.0, tmax = 1e30;
  for (int i = 0; i < 3; ++i) {
    if (std::abs(d(i)) < 1e-12) {
      if (o(i) < b.lo(i) || o(i) > b.hi(i)) return false;
      continue;
    }
    double t1 = (b.lo(i) - o(i)) / d(i), t2 = (b.hi(i) - o(i)) / d(i);
    if (t1 > t2) std::swap(t1, t2);
    tmin = std::max(tmin, t1);
    tmax = std::min(tmax, t2);
  }
  if (tmax < tmin || tmin <= 0) return false;
  *t = tmin;
  return true;
}

/// Organized cloud seen by a camera at T_world_cam, with Gaussian depth noise `sigma` [m].
inline datasets::OrganizedCloud RayCast(const CorridorScene& s,
                                        const datasets::PinholeIntrinsics& k,
                                        const Pose& T_world_cam, double sigma, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  datasets::OrganizedCloud cloud(k.width, k.height, datasets::SensorModel::kPinhole);
  const Eigen::Matrix3d R = T_world_cam.linear();
  const Eigen::Vector3d o = T_world_cam.translation();
  for (int r = 0; r < k.height; ++r) {
    for (int c = 0; c < k.width; ++c) {
      const Eigen::Vector3d d_cam((c - k.cx) / k.fx, (r - k.cy) / k.fy, 1.0);
      const Eigen::Vector3d d = R * d_cam;
      double best = 1e30;
      for (const auto& [n, off] : s.planes) {
        const double den = n.dot(d);
        if (std::abs(den) < 1e-12) continue;
        const double t = (off - n.dot(o)) / den;
        if (t > 0 && t < best) best = t;
      }
      for (const Box& b : s.boxes) {
        double t;
        if (RayBox(o, d, b, &t) && t < best) best = t;
      }
      if (best > s.max_range) continue;  // d_cam.z = 1, so t is the depth
      const double z = best + sigma * g(rng);
      cloud.at(r, c) = (d_cam * z).cast<float>();
    }
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

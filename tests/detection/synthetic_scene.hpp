#pragma once
// A small ray-caster for detector tests: a room (floor, back wall, left wall, a tilted right wall)
// with a box standing on the floor, seen by a 640x480 pinhole camera (fx = fy = 525). Every pixel
// knows which plane it hit, so detections can be checked against exact planes.
#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"

namespace planeslam::test {

struct GtPlane {
  Eigen::Vector3d normal;  // unit, n.p = d, d > 0
  double d;
  // Optional bounds (finite rectangle): lo <= p <= hi per axis.
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(-1e9);
  Eigen::Vector3d hi = Eigen::Vector3d::Constant(1e9);
};

struct SyntheticFrame {
  datasets::OrganizedCloud cloud;
  std::vector<GtPlane> planes;
  std::vector<int> gt_labels;  // index into planes, -1 = no hit
};

inline std::vector<GtPlane> RoomPlanes() {
  std::vector<GtPlane> planes;
  const double deg = M_PI / 180.0;
  planes.push_back({Eigen::Vector3d(0, 1, 0), 1.0});   // floor 1 m below (y down)
  planes.push_back({Eigen::Vector3d(0, 0, 1), 3.8});   // back wall
  planes.push_back({Eigen::Vector3d(-1, 0, 0), 1.4});  // left wall
  // Right wall through (1.5, 0, 2) turned 20 deg about y.
  const Eigen::Vector3d nr(std::cos(20 * deg), 0, -std::sin(20 * deg));
  planes.push_back({nr, nr.dot(Eigen::Vector3d(1.5, 0, 2))});
  // Box front face z = 1.5 and its left side x = 0.1, standing on the floor.
  GtPlane front{Eigen::Vector3d(0, 0, 1), 1.5};
  front.lo = Eigen::Vector3d(0.1, 0.2, 1.5 - 1e-9);
  front.hi = Eigen::Vector3d(0.7, 1.0, 1.5 + 1e-9);
  planes.push_back(front);
  GtPlane side{Eigen::Vector3d(1, 0, 0), 0.1};
  side.lo = Eigen::Vector3d(0.1 - 1e-9, 0.2, 1.5);
  side.hi = Eigen::Vector3d(0.1 + 1e-9, 1.0, 2.0);
  planes.push_back(side);
  return planes;
}

/// Renders the planes; depth noise sigma(z) = noise_z2 * z^2 along the ray (seeded).
inline SyntheticFrame RenderScene(const std::vector<GtPlane>& planes, double noise_z2 = 0.0,
                                  unsigned seed = 1, int width = 640, int height = 480) {
  SyntheticFrame f;
  f.planes = planes;
  f.cloud = datasets::OrganizedCloud(width, height);
  f.gt_labels.assign(static_cast<std::size_t>(width) * height, -1);
  const double fx = 525, fy = 525, cx = (width - 1) / 2.0, cy = (height - 1) / 2.0;
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3d ray((u - cx) / fx, (v - cy) / fy, 1.0);
      double best_t = std::numeric_limits<double>::infinity();
      int best = -1;
      for (std::size_t i = 0; i < planes.size(); ++i) {
        const double nr = planes[i].normal.dot(ray);
        if (nr <= 1e-12) continue;
        const double t = planes[i].d / nr;
        const Eigen::Vector3d p = t * ray;
        if ((p.array() < planes[i].lo.array()).any() || (p.array() > planes[i].hi.array()).any())
          continue;
        if (t < best_t) {
          best_t = t;
          best = static_cast<int>(i);
        }
      }
      if (best < 0) continue;
      double z = best_t;  // ray has z = 1, so t is the depth
      if (noise_z2 > 0) z += noise_z2 * z * z * gauss(rng);
      const Eigen::Vector3d p = z * ray;
      const std::size_t idx = static_cast<std::size_t>(v) * width + u;
      f.cloud.points[idx] = p.cast<float>();
      f.gt_labels[idx] = best;
    }
  }
  return f;
}

}  // namespace planeslam::test

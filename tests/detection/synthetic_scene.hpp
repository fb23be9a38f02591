#pragma once
// Detector test scenes rendered by the simulation library (datasets/sim). A test describes its
// planes in the camera's optical frame (x right, y down, z forward), each cut to an axis-aligned
// box (or unbounded); the library's pinhole sensor renders them from the origin, and its label
// image says which plane each pixel shows. The default room: floor, back wall, left wall, a right
// wall turned 20 deg about the vertical (seen edge-on at the image's right border) and a box on
// the floor, seen by a 640x480 camera (fx = fy = 525).
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <utility>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/synthetic_sensor.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::test {

/// A ground-truth plane n.p = d with d > 0 (n points away from the camera), cut to lo <= p <= hi.
struct GtPlane {
  Eigen::Vector3d normal;
  double d;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(-1e9);
  Eigen::Vector3d hi = Eigen::Vector3d::Constant(1e9);
};

/// A rendered frame: the cloud, the planes in the camera frame, and per pixel the index of the
/// plane it shows (-1: no return).
struct SyntheticFrame {
  datasets::OrganizedCloud cloud;
  std::vector<GtPlane> planes;
  std::vector<int> gt_labels;
};

/// The planes' extent is cut to this box as well: far beyond every test scene, near enough that
/// the sensor's inside-polygon tests keep their precision [m].
constexpr double kSceneExtent = 100.0;

/// The convex polygon where plane n.p = d meets the box [lo, hi], corners counter-clockwise seen
/// from the side `n` points to; empty when they do not meet in an area.
inline std::vector<Eigen::Vector3d> PlaneInBox(const Eigen::Vector3d& n, double d,
                                               const Eigen::Vector3d& lo,
                                               const Eigen::Vector3d& hi) {
  std::vector<Eigen::Vector3d> corners;
  // Crossings of the plane with the box's twelve edges (edges along axis a, at the four
  // combinations of the other two axes' bounds).
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    for (int k = 0; k < 4; ++k) {
      Eigen::Vector3d p;
      p(b) = (k & 1) ? hi(b) : lo(b);
      p(c) = (k & 2) ? hi(c) : lo(c);
      if (std::abs(n(a)) < 1e-12) continue;
      p(a) = (d - n(b) * p(b) - n(c) * p(c)) / n(a);
      if (p(a) < lo(a) - 1e-12 || p(a) > hi(a) + 1e-12) continue;
      p(a) = std::clamp(p(a), lo(a), hi(a));
      bool duplicate = false;
      for (const auto& q : corners) duplicate = duplicate || (q - p).norm() < 1e-9;
      if (!duplicate) corners.push_back(p);
    }
  }
  if (corners.size() < 3) return {};
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : corners) centre += p;
  centre /= static_cast<double>(corners.size());
  const Eigen::Vector3d u =
      (std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY()).cross(n)
          .normalized();
  const Eigen::Vector3d v = n.cross(u);
  auto angle = [&](const Eigen::Vector3d& p) {
    return std::atan2((p - centre).dot(v), (p - centre).dot(u));
  };
  std::sort(corners.begin(), corners.end(),
            [&](const Eigen::Vector3d& p, const Eigen::Vector3d& q) { return angle(p) < angle(q); });
  return corners;
}

/// The planes as a simulation scene: plane i has id i + 1 and faces the origin.
inline datasets::SyntheticScene SceneOf(const std::vector<GtPlane>& planes) {
  datasets::SyntheticScene scene;
  scene.name = "test";
  const Eigen::Vector3d far = Eigen::Vector3d::Constant(kSceneExtent);
  for (std::size_t i = 0; i < planes.size(); ++i) {
    datasets::ScenePlane plane;
    plane.id = static_cast<int>(i) + 1;
    plane.name = "plane" + std::to_string(i);
    plane.normal = -planes[i].normal;
    plane.d = -planes[i].d;
    auto polygon = PlaneInBox(plane.normal, plane.d, planes[i].lo.cwiseMax(-far),
                              planes[i].hi.cwiseMin(far));
    if (!polygon.empty()) plane.polygons.push_back(std::move(polygon));
    scene.planes.push_back(std::move(plane));
  }
  return scene;
}

/// The test camera: fx = fy = 525 with the principal point at the image centre, depth noise
/// sigma(z) = noise_z2 * z^2 along the ray, and none of the sensor's dropouts (every return up
/// to 8 m counts, however grazing, and depth edges keep both sides).
inline datasets::PinholeSimConfig TestCamera(int width, int height, double noise_z2) {
  datasets::PinholeSimConfig config;
  config.intrinsics.width = width;
  config.intrinsics.height = height;
  config.intrinsics.fx = config.intrinsics.fy = 525.0;
  config.intrinsics.cx = (width - 1) / 2.0;
  config.intrinsics.cy = (height - 1) / 2.0;
  config.noise = noise_z2 > 0.0;
  config.noise_k = noise_z2;
  config.max_incidence_deg = 90.0;
  config.edge_dropout = false;
  return config;
}

/// A rendered frame of a simulation scene seen from T_world_sensor: the labels become indices
/// into `planes`, the scene's planes in the sensor frame with d >= 0.
inline SyntheticFrame FrameOf(const datasets::SyntheticScene& scene,
                              const datasets::SyntheticRender& render,
                              const Pose& T_world_sensor) {
  SyntheticFrame f;
  f.cloud = render.cloud;
  const Pose T_sensor_world = T_world_sensor.inverse();
  for (const auto& plane : scene.planes) {
    GtPlane gt{T_sensor_world.linear() * plane.normal,
               plane.d - plane.normal.dot(T_world_sensor.translation())};
    if (gt.d < 0.0) {
      gt.normal = -gt.normal;
      gt.d = -gt.d;
    }
    f.planes.push_back(gt);
  }
  f.gt_labels.resize(render.labels.data.size());
  for (std::size_t i = 0; i < f.gt_labels.size(); ++i) {
    f.gt_labels[i] = render.cloud.IsValid(i) ? static_cast<int>(render.labels.data[i]) - 1 : -1;
  }
  return f;
}

/// Renders `planes` with the test camera at the origin; `seed` drives the depth noise.
inline SyntheticFrame RenderScene(const std::vector<GtPlane>& planes, double noise_z2 = 0.0,
                                  unsigned seed = 1, int width = 640, int height = 480) {
  const auto sensor =
      datasets::MakePinholeSensor(SceneOf(planes), TestCamera(width, height, noise_z2));
  SyntheticFrame f = FrameOf(SceneOf(planes), sensor->Render(Pose::Identity(), seed),
                             Pose::Identity());
  f.planes = planes;
  return f;
}

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

}  // namespace planeslam::test

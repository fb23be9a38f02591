// ViewBins: whether a scan's lines of sight reached a point, for a depth camera and a spinning
// LiDAR, over a randomized family of scenes (a wall with a box in front of it).
#include "planeslam/mapping/view_bins.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace planeslam::mapping {
namespace {

/// Range along a unit ray to the wall x = wall (facing the sensor) with an occluding box
/// [box_near, box_far] x [-h, h]^2 in front of it; NaN when the ray misses both.
double CastRay(const Eigen::Vector3d& ray, double wall, double box_near, double h) {
  if (!(ray.x() > 1e-9)) return std::nan("");
  const double t_box = box_near / ray.x();
  const Eigen::Vector3d hit = t_box * ray;
  if (std::abs(hit.y()) <= h && std::abs(hit.z()) <= h) return t_box;
  return wall / ray.x();
}

datasets::OrganizedCloud Render(int width, int height, bool spherical, double wall,
                                double box_near, double h) {
  datasets::OrganizedCloud cloud(width, height,
                                 spherical ? datasets::SensorModel::kSpherical
                                           : datasets::SensorModel::kPinhole);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      Eigen::Vector3d ray;
      if (spherical) {  // x forward, z up: 360 deg azimuth, +-15 deg elevation
        const double az = 2.0 * M_PI * (c + 0.5) / width - M_PI;
        const double el = (15.0 - 30.0 * (r + 0.5) / height) * M_PI / 180.0;
        ray = {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
      } else {  // optical frame rotated to look along +x: 60 x 45 deg
        const double u = std::tan(30.0 * M_PI / 180.0) * (2.0 * (c + 0.5) / width - 1.0);
        const double v = std::tan(22.5 * M_PI / 180.0) * (2.0 * (r + 0.5) / height - 1.0);
        ray = Eigen::Vector3d(1.0, -u, -v).normalized();
      }
      const double t = CastRay(ray, wall, box_near, h);
      cloud.at(r, c) = std::isfinite(t) ? Eigen::Vector3f((t * ray).cast<float>())
                                        : Eigen::Vector3f::Constant(std::nanf(""));
    }
  }
  return cloud;
}

TEST(ViewBins, TellsSeenFromHiddenAndUnseenOverRandomScenes) {
  // 60 draws per sensor, failure budget 0: a point of the wall beside the box is reached, one
  // behind the box is not, one in front of the wall is, one behind the wall is not, and a
  // direction outside a depth camera's view is not.
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> wall_at(3.0, 8.0), near_share(0.3, 0.7), half(0.3, 0.6);
  for (bool spherical : {false, true}) {
    for (int draw = 0; draw < 60; ++draw) {
      SCOPED_TRACE((spherical ? "spherical draw " : "pinhole draw ") + std::to_string(draw));
      const double wall = wall_at(rng);
      const double box_near = near_share(rng) * wall;
      const double h = half(rng) * box_near * 0.5;
      const datasets::OrganizedCloud cloud =
          spherical ? Render(2048, 64, true, wall, box_near, h)
                    : Render(320, 240, false, wall, box_near, h);
      const ViewBins view(cloud, 1);
      const double tolerance = 0.05;
      // Beside the box's shadow on the wall, by a tenth of the wall's distance (inside the
      // depth camera's 30 deg half width: the shadow's half width is at most 0.3 of it).
      const double side = wall * (h / box_near + 0.1);
      const Eigen::Vector3d beside(wall, side, 0.0);
      EXPECT_TRUE(view.Reaches(beside, tolerance));
      EXPECT_TRUE(view.Reaches(Eigen::Vector3d(0.8 * wall, side * 0.8, 0.0), tolerance));
      EXPECT_FALSE(view.Reaches(Eigen::Vector3d(wall + 0.5, side * (wall + 0.5) / wall, 0.0),
                                tolerance));
      // Behind the box, on the wall: hidden.
      EXPECT_FALSE(view.Reaches(Eigen::Vector3d(wall, 0.0, 0.0), tolerance));
      EXPECT_TRUE(view.Reaches(Eigen::Vector3d(0.9 * box_near, 0.0, 0.0), tolerance));
      // Behind the sensor: a depth camera never saw it; a LiDAR saw nothing there either.
      EXPECT_FALSE(view.Reaches(Eigen::Vector3d(-wall, 0.0, 0.0), tolerance));
    }
  }
}

TEST(ViewBins, EmptyCloudSeesNothing) {
  datasets::OrganizedCloud cloud(4, 3);
  for (auto& p : cloud.points) p = Eigen::Vector3f::Constant(std::nanf(""));
  const ViewBins view(cloud, 1);
  EXPECT_TRUE(view.empty());
  EXPECT_FALSE(view.Reaches(Eigen::Vector3d(0, 0, 1), 1.0));
}

}  // namespace
}  // namespace planeslam::mapping

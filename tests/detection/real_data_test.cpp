// Regression on real frames (skipped without the shared data): the first TUM fr3
// structure_notexture_far depth frame and the first organized laser scan of the "andreashaus".
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <string>

#include "planeslam/datasets/depth_image.hpp"
#include "planeslam/datasets/pcd_io.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/detection/point_region_growing.hpp"
#include "test_support.hpp"

namespace planeslam::detection {
namespace {

datasets::OrganizedCloud FirstTumFrame() {
  const auto dir = test::DataDir() / "tum_fr3_structure_notexture_far";
  std::ifstream list(dir / "depth.txt");
  std::string line;
  while (std::getline(list, line)) {
    if (line.empty() || line[0] == '#') continue;
    break;
  }
  const std::string file = line.substr(line.find(' ') + 1);
  datasets::PinholeIntrinsics k;  // intrinsics.yaml: fx 535.4 fy 539.2 cx 320.1 cy 247.6
  k.fx = 535.4;
  k.fy = 539.2;
  k.cx = 320.1;
  k.cy = 247.6;
  return datasets::ReadDepthCloud((dir / file).string(), k, 5000.0);
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::min(1.0, std::abs(a.dot(b)))) * 180.0 / M_PI;
}

double AssignedFraction(const Segmentation& seg, const datasets::OrganizedCloud& cloud) {
  std::size_t assigned = 0;
  for (int l : seg.labels) assigned += l >= 1 ? 1 : 0;
  return static_cast<double>(assigned) / cloud.CountValid();
}

/// The scene: a Kinect passes a zig-zag wooden structure standing on the floor, a wall behind.
/// Known geometry, not numbers from a previous run: the floor faces the camera's y axis (the
/// camera is held upright, pitched down); the structure's faces and the wall stand on the floor
/// (normals perpendicular to it); the structure has faces in two orientations (its zig-zag) and
/// parallel faces at different offsets; the wall is the far large plane (beyond 3.5 m).
void CheckTumScene(const Segmentation& seg, const datasets::OrganizedCloud& cloud,
                   const std::string& what) {
  EXPECT_GE(AssignedFraction(seg, cloud), 0.8) << what;
  const Plane* floor = nullptr;
  for (const auto& p : seg.planes) {
    if (p.point_count >= 5000 && AngleDeg(p.normal, Eigen::Vector3d::UnitY()) < 30) {
      floor = &p;
      break;  // planes are sorted by size: the largest such plane
    }
  }
  ASSERT_NE(floor, nullptr) << what << ": no floor";
  std::vector<const Plane*> faces;  // near upright planes: the structure
  const Plane* wall = nullptr;
  for (const auto& p : seg.planes) {
    if (p.point_count < 500 || &p == floor) continue;
    const double to_floor = AngleDeg(p.normal, floor->normal);
    if (p.centroid.norm() > 3.5 && p.point_count >= 5000 && to_floor > 60 && !wall) wall = &p;
    if (p.centroid.norm() < 3.0 && to_floor > 80) faces.push_back(&p);
  }
  ASSERT_NE(wall, nullptr) << what << ": no wall";
  ASSERT_GE(faces.size(), 3u) << what;
  // Two large parallel faces at different offsets, and a face of the other zig-zag orientation.
  ASSERT_GE(faces[0]->point_count, 20000) << what;
  bool parallel = false, other = false;
  for (std::size_t i = 1; i < faces.size(); ++i) {
    const double a = AngleDeg(faces[0]->normal, faces[i]->normal);
    if (a < 5 && std::abs(faces[0]->d - faces[i]->d) > 0.3 && faces[i]->point_count >= 5000)
      parallel = true;
    if (a > 45) other = true;
  }
  EXPECT_TRUE(parallel) << what << ": no second parallel face";
  EXPECT_TRUE(other) << what << ": no face of the other orientation";
}

TEST(RealData, TumStructureNotextureFarFirstFrame) {
  PLANESLAM_REQUIRE_DATA();
  const auto cloud = FirstTumFrame();
  ASSERT_EQ(cloud.width, 640);
  CheckTumScene(GridRegionGrowing(DetectionParams(), GridParams()).Detect(cloud), cloud, "grid3");
  CheckTumScene(PointRegionGrowing(DetectionParams(), PointParams()).Detect(cloud), cloud, "point");
  DetectionParams fast_params;
  GridParams fast_grid;
  UseFastVariant(fast_params, fast_grid);
  const Segmentation fast = GridRegionGrowing(fast_params, fast_grid).Detect(cloud);
  CheckTumScene(fast, cloud, "grid-fast");
  // The grid-level refinement also gives a plane the grids along its rim that growth left out
  // when they fit it, so most valid pixels are assigned.
  EXPECT_GT(AssignedFraction(fast, cloud), 0.9);
}

/// Laser scan of a house (3DTK convention: y up, left-handed), centimetres -> metres. The
/// ground/floor is a large plane facing -y below the scanner, the ceiling one facing +y above
/// it; walls are upright (normal perpendicular to y): the big wall in front (>= 10000 points) and
/// a wall at an angle to it (the scan sees mostly one wall direction; the other is a short
/// stretch of 1500-2500 points).
void CheckLaserScene(const Segmentation& seg, const std::string& what) {
  bool ground = false, ceiling = false;
  std::vector<const Plane*> walls;
  for (const auto& p : seg.planes) {
    if (p.point_count < 1000) continue;
    const double to_y = AngleDeg(p.normal, Eigen::Vector3d::UnitY());
    if (p.point_count >= 2000 && to_y < 10 && p.normal.y() < 0 && p.centroid.y() < 0) ground = true;
    if (p.point_count >= 2000 && to_y < 10 && p.normal.y() > 0 && p.centroid.y() > 0)
      ceiling = true;
    if (to_y > 80) walls.push_back(&p);
  }
  EXPECT_TRUE(ground) << what;
  EXPECT_TRUE(ceiling) << what;
  ASSERT_FALSE(walls.empty()) << what;
  EXPECT_GE(walls[0]->point_count, 10000) << what;
  bool two_directions = false;
  for (std::size_t j = 1; j < walls.size(); ++j)
    if (AngleDeg(walls[0]->normal, walls[j]->normal) > 30) two_directions = true;
  EXPECT_TRUE(two_directions) << what << ": " << walls.size() << " upright planes";
}

TEST(RealData, LaserScanHouse) {
  PLANESLAM_REQUIRE_DATA();
  const auto cloud = datasets::ReadPcd((test::DataDir() / "laser_scans" / "scan000.pcd").string(),
                                       0.01, datasets::SensorModel::kSpherical);
  ASSERT_EQ(cloud.width * cloud.height, 513 * 633);
  // config/detection_laser.yaml: the paper's constant thresholds.
  DetectionParams params;
  params.model = ThresholdModel::kConstant;
  params.eta_deg = 15;
  params.gamma = 0.03;
  params.epsilon = 2.5e-4;
  params.delta = 0.3;
  params.theta = 300;
  params.sigma0 = 0.01;
  params.sigma_z2 = 0.0;
  CheckLaserScene(GridRegionGrowing(params, GridParams()).Detect(cloud), "grid3");
  CheckLaserScene(PointRegionGrowing(params, PointParams()).Detect(cloud), "point");
  DetectionParams fast_params = params;
  GridParams fast_grid;
  UseFastVariant(fast_params, fast_grid);
  CheckLaserScene(GridRegionGrowing(fast_params, fast_grid).Detect(cloud), "grid-fast");
}

}  // namespace
}  // namespace planeslam::detection

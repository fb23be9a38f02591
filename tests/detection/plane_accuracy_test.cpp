// Plane accuracy on rendered scenes with Kinect-like noise along the ray: the final fit along the
// rays (DetectionParams::ray_fit) must remove the eigen fit's bias on surfaces seen at grazing
// angles, a narrow plane must give back the strip of its neighbours that growth hands it at a
// crease, and the count term of epsilon must keep a board apart from the wall behind it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <utility>

#include "detection_checks.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/detection/point_region_growing.hpp"
#include "synthetic_scene.hpp"

namespace planeslam::detection {
namespace {

constexpr double kKinectNoise = 1.425e-3;  // sigma(z) = 1.425e-3 z^2 along the ray

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::min(1.0, std::abs(a.dot(b)))) * 180.0 / M_PI;
}

std::unique_ptr<PlaneDetector> Make(const std::string& method, bool ray_fit) {
  DetectionParams params;
  params.ray_fit = ray_fit;
  if (method == "grid") return std::make_unique<GridRegionGrowing>(params, GridParams());
  return std::make_unique<PointRegionGrowing>(params, PointParams());
}

/// The detected plane holding most pixels of ground-truth plane g (-1: none), and how many of
/// its pixels belong to other ground-truth planes.
int Majority(const test::SyntheticFrame& frame, const Segmentation& seg, int g, int* foreign) {
  std::vector<int> overlap(seg.planes.size() + 1, 0);
  for (std::size_t i = 0; i < frame.gt_labels.size(); ++i) {
    if (frame.gt_labels[i] == g && seg.labels[i] >= 1) ++overlap[seg.labels[i]];
  }
  int best = -1;
  for (std::size_t id = 1; id < overlap.size(); ++id) {
    if (overlap[id] > 0 && (best < 0 || overlap[id] > overlap[best])) best = static_cast<int>(id);
  }
  *foreign = 0;
  for (std::size_t i = 0; best >= 1 && i < frame.gt_labels.size(); ++i) {
    if (seg.labels[i] == best && frame.gt_labels[i] != g) ++*foreign;
  }
  return best;
}

/// A door recess seen from 2.6 m: wall z = 2.6 for x >= 1, door z = 2.8 for x <= 1, and the
/// jamb x = 1 between them (20 cm deep, seen at about 70 deg incidence, ~6700 px). Plane 2 is
/// the jamb.
std::vector<test::GtPlane> DoorRecess() {
  test::GtPlane wall{Eigen::Vector3d(0, 0, 1), 2.6};
  wall.lo.x() = 1.0;
  test::GtPlane door{Eigen::Vector3d(0, 0, 1), 2.8};
  door.hi.x() = 1.0;
  test::GtPlane jamb{Eigen::Vector3d(1, 0, 0), 1.0};
  jamb.lo.z() = 2.6;
  jamb.hi.z() = 2.8;
  return {wall, door, jamb};
}

TEST(RayFit, GrazingFloorWithoutTheEigenFitBias) {
  // A floor 0.8 m below the camera, pitched 12 deg: rays meet it 3.4-8 m away at 77-85 deg
  // incidence. Over five noise draws the eigen fit's normal is pulled towards the rays; the ray
  // fit's is not.
  const double deg = M_PI / 180.0;
  const Eigen::Vector3d n(0, std::cos(12 * deg), -std::sin(12 * deg));
  for (const char* method : {"grid", "point"}) {
    double error_sum[2] = {0.0, 0.0};
    for (unsigned seed = 1; seed <= 5; ++seed) {
      const auto frame = test::RenderScene({{n, 0.8}}, kKinectNoise, seed);
      for (int ray = 0; ray < 2; ++ray) {
        const Segmentation seg = Make(method, ray == 1)->Detect(frame.cloud);
        int foreign = 0;
        const int id = Majority(frame, seg, 0, &foreign);
        ASSERT_GE(id, 1) << method;
        error_sum[ray] += AngleDeg(seg.planes[id - 1].normal, n) / 5.0;
      }
    }
    EXPECT_LT(error_sum[1], 0.01) << method << ": ray fit mean normal error [deg]";
    EXPECT_LT(error_sum[1], 0.5 * error_sum[0]) << method << ": ray fit vs eigen fit [deg]";
  }
}

TEST(RayFit, DoorJambGivesBackItsNeighboursStrip) {
  // Without the ray fit the jamb takes a strip of the wall and the door at its two creases and
  // tilts towards them; with it, the strip's pixels are asked again along the rays and go back.
  const auto planes = DoorRecess();
  for (const char* method : {"grid", "point"}) {
    int foreign_sum[2] = {0, 0};
    for (unsigned seed = 1; seed <= 5; ++seed) {
      const auto frame = test::RenderScene(planes, kKinectNoise, seed);
      const int jamb_pixels =
          static_cast<int>(std::count(frame.gt_labels.begin(), frame.gt_labels.end(), 2));
      ASSERT_GT(jamb_pixels, 6000);
      for (int ray = 0; ray < 2; ++ray) {
        const Segmentation seg = Make(method, ray == 1)->Detect(frame.cloud);
        int foreign = 0;
        const int id = Majority(frame, seg, 2, &foreign);
        ASSERT_GE(id, 1) << method << " seed " << seed;
        foreign_sum[ray] += foreign;
        if (ray == 0) continue;
        EXPECT_LT(AngleDeg(seg.planes[id - 1].normal, planes[2].normal), 0.25)
            << method << " seed " << seed;
        // Offset where the jamb is (its centre), not at the origin 2.7 m away, where the tilt
        // alone moves d by up to 6 mm.
        const Plane& jamb = seg.planes[id - 1];
        EXPECT_LT(std::abs(jamb.normal.dot(Eigen::Vector3d(1.0, 0.0, 2.7)) - jamb.d), 0.002)
            << method << " seed " << seed;
        EXPECT_LT(foreign, jamb_pixels / 10) << method << " seed " << seed;
      }
    }
    EXPECT_LT(foreign_sum[1], foreign_sum[0] / 2) << method;
  }
}

TEST(RayFit, NoiseFreePlanesAreExact) {
  // Without noise every pixel lies on its plane, so the fit is exact up to the float points.
  const auto frame = test::RenderScene(DoorRecess());
  for (const char* method : {"grid", "point"}) {
    const Segmentation seg = Make(method, true)->Detect(frame.cloud);
    for (int g = 0; g < 3; ++g) {
      int foreign = 0;
      const int id = Majority(frame, seg, g, &foreign);
      ASSERT_GE(id, 1) << method << " plane " << g;
      EXPECT_LT(AngleDeg(seg.planes[id - 1].normal, DoorRecess()[g].normal), 1e-3) << method;
      EXPECT_NEAR(seg.planes[id - 1].d, DoorRecess()[g].d, 1e-5) << method;
    }
  }
}

TEST(EpsilonCountSigmas, BoardTwoCentimetresInFrontOfItsWallStaysApart) {
  // A wall 1.7 m away seen at 20 deg, and a 0.8 x 0.6 m board 2 cm in front of it (like a
  // whiteboard). Under Kinect noise (4 mm at 1.7 m) the flat epsilon factor (1.5) lets one region
  // take both through a compromise plane; the count term keeps a large region's MSE near the
  // model's, and the two apart.
  const Eigen::Vector3d n = Eigen::Vector3d(-0.2, -0.23, 0.95).normalized();
  test::GtPlane wall{n, 1.70};
  test::GtPlane board{n, 1.68};
  board.lo = Eigen::Vector3d(-0.6, -0.5, -1e9);
  board.hi = Eigen::Vector3d(0.2, 0.1, 1e9);
  DetectionParams params;
  params.gamma = 0.007;  // as config/detection_synthetic.yaml
  params.epsilon_sigmas = 1.0;
  params.epsilon_count_sigmas = 1.5;
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const auto frame = test::RenderScene({wall, board}, kKinectNoise, seed);
    const int board_pixels =
        static_cast<int>(std::count(frame.gt_labels.begin(), frame.gt_labels.end(), 1));
    ASSERT_GT(board_pixels, 20000);
    for (const char* method : {"grid", "point"}) {
      const std::unique_ptr<PlaneDetector> detector =
          std::string(method) == "grid"
              ? std::unique_ptr<PlaneDetector>(new GridRegionGrowing(params, GridParams()))
              : std::unique_ptr<PlaneDetector>(new PointRegionGrowing(params, PointParams()));
      const Segmentation seg = detector->Detect(frame.cloud);
      int board_foreign = 0, wall_foreign = 0;
      const int board_id = Majority(frame, seg, 1, &board_foreign);
      const int wall_id = Majority(frame, seg, 0, &wall_foreign);
      ASSERT_GE(board_id, 1) << method << " seed " << seed;
      ASSERT_GE(wall_id, 1) << method << " seed " << seed;
      EXPECT_NE(board_id, wall_id) << method << " seed " << seed;
      EXPECT_LT(board_foreign, board_pixels / 100) << method << " seed " << seed;
      EXPECT_LT(std::abs(seg.planes[board_id - 1].d - board.d), 0.005) << method;
      EXPECT_LT(std::abs(seg.planes[wall_id - 1].d - wall.d), 0.005) << method;
    }
  }
}

/// The synthetic room with its right wall turned theta_deg about the vertical through (1.5, 0, 2).
std::vector<test::GtPlane> RoomWithRightWallTurned(double theta_deg) {
  auto planes = test::RoomPlanes();
  const double theta = theta_deg * M_PI / 180.0;
  const Eigen::Vector3d turned(std::cos(theta), 0, -std::sin(theta));
  planes[3] = {turned, turned.dot(Eigen::Vector3d(1.5, 0, 2))};
  return planes;
}

/// A detector of the narrow-wall sweeps: GBRG with k x k grids (6: grid-fast) or, for k = 0, PBRG.
std::unique_ptr<PlaneDetector> SweepDetector(int k) {
  if (k == 0) return std::make_unique<PointRegionGrowing>(DetectionParams(), PointParams());
  DetectionParams params;
  GridParams grid;
  grid.cell_size = k;
  if (k == 6) UseFastVariant(params, grid);
  const std::string name = k == 6 ? "grid-fast" : "";
  return std::make_unique<GridRegionGrowing>(params, grid, name);
}

TEST(KnownAnswers, NarrowGrazingWallWhereverItFalls) {
  // The room's right wall turned from 20 to 23.5 deg about the vertical, rendered 630 to 650 px
  // wide: seen ever more edge-on, it narrows to 6-9 px at the back (2300-8600 px in all), and
  // where grids cut it moves by a pixel from one width to the next. GBRG with 3x3 and 5x5 grids,
  // grid-fast and PBRG find it, and every other plane of 2000 px or more, as exactly as
  // a wide plane. (grid-fast's wall there is a column or two of 6x6 grids across both it and the
  // back wall: fitted and labelled by whole grids, it came out 2.6 cm to 0.9 m off, or mostly
  // missed, on 4 of these 36 renders, until such planes got the pixel-level refinement.)
  for (const double theta_deg : {20.0, 21.0, 22.0, 22.5, 23.0, 23.5}) {
    const auto planes = RoomWithRightWallTurned(theta_deg);
    for (int width = 630; width <= 650; width += 4) {
      const auto frame = test::RenderScene(planes, 0.0, 1, width, 480);
      for (const int k : {3, 5, 6, 0}) {
        const std::unique_ptr<PlaneDetector> detector = SweepDetector(k);
        test::ExpectPlanesFound(frame, detector->Detect(frame.cloud), 2000, 0.5, 0.005,
                                detector->Name() + " wall at " + std::to_string(theta_deg) +
                                    " deg, " + std::to_string(width) + " px");
      }
    }
  }
}

TEST(KnownAnswers, NarrowGrazingWallWithKinectNoise) {
  // The same 36 renders with Kinect noise (sigma 16-21 mm along the ray at the wall's 3.5-3.8
  // m; seeded by the width): every plane of 2000 px or more within 2 deg and 2 cm, the noisy
  // known-answer bound. On the wall the eigen fit is pulled up to 5 cm off by the noise (see
  // ray_fit), and so were the pixels chosen against it: before pixels of no plane were asked
  // again along the rays, grid3's wall came out 2.8 cm off at 23 deg, 638 px; before narrow
  // planes chose their pixels a second time along the rays and were refined from an interior of
  // under half, grid3-fast's 2.1-4.4 cm on three renders; before border grids had a scaled mu
  // and the grids left out grew a second time, grid-fast's wall was mostly missed or 2-14 cm off
  // on 6. grid5 (its wall mostly missed on 2, without those two) does not pass: its grids are
  // about as wide as the wall.
  for (const double theta_deg : {20.0, 21.0, 22.0, 22.5, 23.0, 23.5}) {
    const auto planes = RoomWithRightWallTurned(theta_deg);
    for (int width = 630; width <= 650; width += 4) {
      const auto frame = test::RenderScene(planes, kKinectNoise, width, width, 480);
      for (const int k : {3, 4, 6, 0}) {
        const std::unique_ptr<PlaneDetector> detector = SweepDetector(k);
        test::ExpectPlanesFound(frame, detector->Detect(frame.cloud), 2000, 2.0, 0.02,
                                detector->Name() + " wall at " + std::to_string(theta_deg) +
                                    " deg, " + std::to_string(width) + " px");
      }
    }
  }
}

}  // namespace
}  // namespace planeslam::detection

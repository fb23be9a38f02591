// Property tests of the plane detectors as users get them (app::MakeDetector, default
// configuration), on scenes drawn at random from a fixed seed and rendered by the simulation
// library, so that no single render decides whether a method passes.
//
// Grazing planes: a room (floor, ceiling, back wall, two side walls) seen from inside, one of
// whose side walls meets the back wall in a corner just inside the image border and is seen
// edge-on there. Each draw takes
//   - the image width, 600-660 px (fx = fy = 525, principal point at the centre), so that the
//     grids cut the wall and its corner at every phase;
//   - the side of the grazing wall, and how far inside the border its corner is, 4-60 px;
//   - the angle between the view ray and the wall's normal at the corner, 65-85 deg;
//   - the distance to the corner, 1-4 m, and the other walls, floor and ceiling;
//   - the camera pose, jittered by up to 8 deg of roll, 4 of pitch, 1 of yaw and 3 cm;
//   - the depth noise seed (Kinect v1: sigma(z) = 1.425e-3 z^2 along the ray, truncated at 3
//     sigma; returns up to 88 deg incidence, depth edges dropped).
// For every method and draw, every plane of at least 2000 px must be found within 2 deg and 2 cm
// (the noisy known-answer bound of tests/detection) and mostly covered; noise-free, within
// 0.5 deg and 5 mm. A draw fails when any of its planes does not.
//
// Second scene: the simulation library's rubble (tilted slabs, balls and cylinders on the
// ground) in 24 frames spread along its default camera path, with its default sensor (TUM fr3
// intrinsics, Kinect v1 noise and dropouts); every plane of at least 2000 px within 2 deg and
// 2 cm. A plane not found is a failure.
//
// Budgets: the failures counted on these fixed draws plus a margin of 10% (at least 2) for
// floating-point differences between platforms.
//
//   method        grazing, Kinect noise   grazing, noise-free     rubble
//                 failed draws of 200     failed draws of 60      planes not found of 321
//                 counted   budget        counted   budget        counted   budget
//   grid             0        2              0        2             35        39
//   grid-fast        3        5              0        2             36        40
//   grid-paper      79       88             44       49             93       103
//   point            0        2              0        2             31        35
//   point-paper     24       27              1        3             81        90
//
// The grazing wall has 2000 px or more in 192 of the 200 noisy draws and 59 of the 60 noise-free
// ones. grid and point find every plane in every draw; grid-fast's three failures are ceilings
// (0.4-1 deg, 2-5 cm off), not the grazing wall. The paper-exact methods have neither the
// pixel-level refinement nor the fit along the rays: grid-paper's grids that straddle the
// grazing wall's corner pull its fit (noise-free too), and under noise the eigen fit's bias on
// planes seen at a slant remains, so grid-paper's grazing walls and point-paper's walls, floors
// and ceilings in rooms 2-4 m deep come out a few tenths of a degree and centimetres off,
// beyond these bounds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "config.hpp"
#include "detection/detection_checks.hpp"
#include "detection/synthetic_scene.hpp"
#include "detector_factory.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"

namespace planeslam::app {
namespace {

constexpr double kDeg = M_PI / 180.0;
constexpr double kKinectNoise = 1.425e-3;
constexpr int kMinPixels = 2000;

/// A uniform draw in [lo, hi) from the generator's raw output: std::mt19937 is the same
/// everywhere, the standard distributions are not.
double Uniform(std::mt19937& rng, double lo, double hi) {
  const double u = (static_cast<double>(rng()) + 0.5) / 4294967296.0;
  return lo + (hi - lo) * u;
}

/// Small rotation about the optical frame's axes (x right, y down, z forward) [rad].
Eigen::Matrix3d Rotation(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()) *
          Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()))
      .toRotationMatrix();
}

/// One drawn room, in the frame of the undisturbed camera (the world).
struct GrazingDraw {
  int width = 640;
  std::vector<test::GtPlane> planes;  ///< the grazing wall is planes[0]
  Pose T_world_sensor = Pose::Identity();
  std::uint64_t noise_seed = 1;
  std::string description;
};

GrazingDraw DrawRoom(std::mt19937& rng) {
  GrazingDraw draw;
  draw.width = 600 + static_cast<int>(rng() % 61);
  const double side = rng() % 2 == 0 ? 1.0 : -1.0;  // +1: the right wall is grazing
  const double inside_px = Uniform(rng, 4.0, 60.0);
  const double incidence = Uniform(rng, 65.0, 85.0) * kDeg;
  const double distance = Uniform(rng, 1.0, 4.0);
  const double other_wall = Uniform(rng, 1.0, 2.5);
  const double floor = Uniform(rng, 0.6, 1.5);
  const double ceiling = Uniform(rng, 0.8, 1.8);
  const double roll = Uniform(rng, -8.0, 8.0) * kDeg;
  const double pitch = Uniform(rng, -4.0, 4.0) * kDeg;
  const double yaw = Uniform(rng, -1.0, 1.0) * kDeg;
  Eigen::Vector3d shift;
  for (int i = 0; i < 3; ++i) shift(i) = Uniform(rng, -0.03, 0.03);
  draw.noise_seed = rng();

  // The corner's ray makes theta with the optical axis; the wall runs from the corner towards
  // the camera at phi from the axis, so the ray meets it at 90 deg - (theta - phi) from its
  // normal, and its offset is distance * cos(incidence).
  const double theta = std::atan(((draw.width - 1) / 2.0 - inside_px) / 525.0);
  const double phi = theta - (90.0 * kDeg - incidence);
  const Eigen::Vector3d wall_normal(side * std::cos(phi), 0.0, -std::sin(phi));
  draw.planes.push_back({wall_normal, distance * std::cos(incidence)});
  draw.planes.push_back({Eigen::Vector3d::UnitZ(), distance * std::cos(theta)});  // back wall
  draw.planes.push_back({Eigen::Vector3d(-side, 0.0, 0.0), other_wall});
  draw.planes.push_back({Eigen::Vector3d::UnitY(), floor});     // y points down
  draw.planes.push_back({-Eigen::Vector3d::UnitY(), ceiling});
  draw.T_world_sensor.linear() = Rotation(roll, pitch, yaw);
  draw.T_world_sensor.translation() = shift;

  std::ostringstream what;
  what << draw.width << " px, " << (side > 0 ? "right" : "left") << " wall " << inside_px
       << " px inside at " << incidence / kDeg << " deg, " << distance << " m";
  draw.description = what.str();
  return draw;
}

/// The Kinect-like sensor of the draws (see the top of the file), or a noise-free one.
datasets::PinholeSimConfig DrawCamera(int width, bool noise) {
  datasets::PinholeSimConfig config = test::TestCamera(width, 480, noise ? kKinectNoise : 0.0);
  config.max_incidence_deg = 88.0;
  config.edge_dropout = true;
  return config;
}

/// Pixels of each ground-truth plane.
std::vector<int> PixelsPerPlane(const test::SyntheticFrame& frame) {
  std::vector<int> count(frame.planes.size(), 0);
  for (const int g : frame.gt_labels) {
    if (g >= 0) ++count[static_cast<std::size_t>(g)];
  }
  return count;
}

struct Tally {
  int draws = 0;
  int failed = 0;
  int grazing_checked = 0;  ///< draws whose grazing wall had at least kMinPixels
  int grazing_failed = 0;
};

Tally RunGrazingDraws(const std::string& method, int draws, bool noise, double max_angle_deg,
                      double max_offset_m) {
  const Config config;
  const auto detector = MakeDetector(method, config);
  std::mt19937 rng(noise ? 31 : 37);
  Tally tally;
  for (int i = 0; i < draws; ++i) {
    const GrazingDraw draw = DrawRoom(rng);
    const datasets::SyntheticScene scene = test::SceneOf(draw.planes);
    const auto sensor = datasets::MakePinholeSensor(scene, DrawCamera(draw.width, noise));
    const test::SyntheticFrame frame =
        test::FrameOf(scene, sensor->Render(draw.T_world_sensor, draw.noise_seed),
                      draw.T_world_sensor);
    const auto failures = test::PlanesNotFound(frame, detector->Detect(frame.cloud), kMinPixels,
                                               max_angle_deg, max_offset_m);
    ++tally.draws;
    const int grazing_pixels = PixelsPerPlane(frame)[0];
    tally.grazing_checked += grazing_pixels >= kMinPixels;
    if (failures.empty()) continue;
    ++tally.failed;
    bool grazing = false;
    for (const auto& f : failures) grazing = grazing || f.plane == 0;
    tally.grazing_failed += grazing;
    std::cout << method << " draw " << i << " (" << draw.description << ", wall "
              << grazing_pixels << " px): " << failures.front().what << "\n";
  }
  std::cout << method << ": " << tally.failed << " of " << tally.draws << " draws failed ("
            << tally.grazing_failed << " on the grazing wall; the wall had " << kMinPixels
            << " px or more in " << tally.grazing_checked << ")\n";
  return tally;
}

/// Failures allowed per method (see the table at the top).
struct Budget {
  int noisy;
  int noise_free;
};
const std::map<std::string, Budget>& Budgets() {
  static const std::map<std::string, Budget> budgets = {
      {"grid", {2, 2}},  {"grid-fast", {5, 2}},  {"grid-paper", {88, 49}},
      {"point", {2, 2}}, {"point-paper", {27, 3}}};
  return budgets;
}

class GrazingPlanes : public ::testing::TestWithParam<std::string> {};

TEST_P(GrazingPlanes, FoundUnderKinectNoiseWithinTheBudget) {
  const Tally tally = RunGrazingDraws(GetParam(), 200, true, 2.0, 0.02);
  RecordProperty("failed_draws", tally.failed);
  // The draws must test what they are meant to: most put a wall of 2000 px or more edge-on.
  EXPECT_GT(tally.grazing_checked, tally.draws / 2);
  EXPECT_LE(tally.failed, Budgets().at(GetParam()).noisy);
}

TEST_P(GrazingPlanes, FoundNoiseFreeWithinTheBudget) {
  const Tally tally = RunGrazingDraws(GetParam(), 60, false, 0.5, 0.005);
  RecordProperty("failed_draws", tally.failed);
  EXPECT_GT(tally.grazing_checked, tally.draws / 2);
  EXPECT_LE(tally.failed, Budgets().at(GetParam()).noise_free);
}

/// Planes of at least kMinPixels over `frames` frames spread along the rubble's default path,
/// and how many of them the method does not find within the noisy bounds.
struct RubbleTally {
  int planes = 0;
  int missed = 0;
};

RubbleTally RunRubble(const std::string& method, int frames) {
  const datasets::SyntheticSequence seq(
      datasets::SyntheticConfig::ForScene(datasets::SceneKind::kRubble));
  const Config config;
  const auto detector = MakeDetector(method, config);
  RubbleTally tally;
  for (int k = 0; k < frames; ++k) {
    const std::size_t index = seq.Size() * static_cast<std::size_t>(k) / frames;
    const datasets::SyntheticFrame f = seq.Generate(index);
    datasets::SyntheticRender render;
    render.cloud = f.frame.cloud;
    render.labels = f.labels;
    const test::SyntheticFrame frame = test::FrameOf(seq.scene(), render, *seq.GroundTruth(index));
    for (const auto& count : PixelsPerPlane(frame)) tally.planes += count >= kMinPixels;
    const auto failures =
        test::PlanesNotFound(frame, detector->Detect(frame.cloud), kMinPixels, 2.0, 0.02);
    tally.missed += static_cast<int>(failures.size());
    for (const auto& failure : failures) {
      std::cout << method << " rubble frame " << index << ": " << failure.what << "\n";
    }
  }
  std::cout << method << ": " << tally.missed << " of " << tally.planes
            << " rubble planes not found\n";
  return tally;
}

/// Failures allowed per method on the rubble (see the top): planes not found.
const std::map<std::string, int>& RubbleBudgets() {
  static const std::map<std::string, int> budgets = {
      {"grid", 39}, {"grid-fast", 40}, {"grid-paper", 103}, {"point", 35}, {"point-paper", 90}};
  return budgets;
}

class SecondScene : public ::testing::TestWithParam<std::string> {};

TEST_P(SecondScene, RubblePlanesFoundWithinTheBudget) {
  const RubbleTally tally = RunRubble(GetParam(), 24);
  RecordProperty("missed_planes", tally.missed);
  EXPECT_GT(tally.planes, 100);
  EXPECT_LE(tally.missed, RubbleBudgets().at(GetParam()));
}

std::string MethodTestName(const ::testing::TestParamInfo<std::string>& info) {
  std::string name = info.param;
  for (char& c : name) c = c == '-' ? '_' : c;
  return name;
}

INSTANTIATE_TEST_SUITE_P(Methods, GrazingPlanes, ::testing::ValuesIn(DetectorMethods()),
                         MethodTestName);
INSTANTIATE_TEST_SUITE_P(Methods, SecondScene, ::testing::ValuesIn(DetectorMethods()),
                         MethodTestName);

}  // namespace
}  // namespace planeslam::app

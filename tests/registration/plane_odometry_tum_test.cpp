// Regression on real data: plane odometry on the first 60 frames of TUM fr3
// structure_notexture_far (GBRG planes), against the motion-capture ground truth.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "planeslam/datasets/tum_sequence.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/registration/plane_odometry.hpp"
#include "test_support.hpp"

namespace planeslam::registration {
namespace {

TEST(PlaneOdometryTum, FirstSixtyFramesOfStructureNotextureFar) {
  PLANESLAM_REQUIRE_DATA();
  const auto folder = test::DataDir() / "tum_fr3_structure_notexture_far";
  if (!std::filesystem::is_directory(folder)) GTEST_SKIP() << "missing " << folder;
  const auto seq = datasets::OpenTumSequence(folder.string(), datasets::SensorConfig());
  const detection::GridRegionGrowing detector{detection::DetectionParams{},
                                              detection::GridParams{}};
  PlaneOdometry odometry;
  const std::size_t frames = std::min<std::size_t>(60, seq->Size());
  int converged = 0, steps = 0;
  for (std::size_t i = 0; i < frames; ++i) {
    const datasets::Frame f = seq->Load(i);
    const OdometryStep s = odometry.Process(f.timestamp, f.cloud, detector.Detect(f.cloud));
    ASSERT_TRUE(s.T_world_sensor.matrix().allFinite());
    ASSERT_TRUE(s.covariance.allFinite());
    if (!s.first_frame) {
      ++steps;
      converged += s.registration.converged && !s.registration.degenerate ? 1 : 0;
    }
  }
  // Most frames see enough planes (measured: 1 degenerate pair of the first 55).
  EXPECT_GE(converged, steps * 8 / 10);
  // RPE over 30 frames (~1 s), TUM/evo definition E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j).
  // Measured: 7.4 cm / 1.1 deg rmse over these 26 pairs (3.5 cm / 1.3 deg on all 252 frames);
  // the bounds leave room for detector changes but catch a broken registration.
  const auto& tr = odometry.trajectory();
  double sum_t = 0, sum_r = 0;
  int pairs = 0;
  for (std::size_t i = 0; i + 30 < tr.size(); ++i) {
    const auto a = seq->GroundTruth(i), b = seq->GroundTruth(i + 30);
    if (!a || !b) continue;
    const Pose e = (a->inverse() * *b).inverse() * (tr.poses[i].inverse() * tr.poses[i + 30]);
    sum_t += e.translation().squaredNorm();
    sum_r += std::pow(LogSO3(e.linear()).norm(), 2);
    ++pairs;
  }
  ASSERT_GT(pairs, 20);
  const double rmse_t = std::sqrt(sum_t / pairs);
  const double rmse_r_deg = std::sqrt(sum_r / pairs) * 180.0 / M_PI;
  RecordProperty("rpe_1s_translation_rmse_m", std::to_string(rmse_t));
  RecordProperty("rpe_1s_rotation_rmse_deg", std::to_string(rmse_r_deg));
  EXPECT_LT(rmse_t, 0.15);
  EXPECT_LT(rmse_r_deg, 3.0);
}

}  // namespace
}  // namespace planeslam::registration

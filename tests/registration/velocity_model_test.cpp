// Constant-velocity prediction from recent motions: mean rate over a window of measured time,
// scaled to the next interval, forgetting what is older than the window; translation and rotation
// kept apart; a held part's drift correction spread over the frames it accumulated in.
#include "planeslam/registration/velocity_model.hpp"

#include <gtest/gtest.h>

namespace planeslam::registration {
namespace {

Pose Motion(double tx, double yaw) {
  Pose T = Pose::Identity();
  T.linear() = ExpSO3(Eigen::Vector3d(0.0, 0.0, yaw));
  T.translation() << tx, 0.0, 0.0;
  return T;
}

/// Frames first..last, one every `dt` seconds, each moving by `motion`; with
/// translation_known = false, frames whose translation the prior held.
void AddFrames(VelocityModel* model, int first, int last, double dt, const Pose& motion,
               bool translation_known = true) {
  for (int i = first; i <= last; ++i) model->Add(dt * i, dt, motion, translation_known);
}

TEST(VelocityModel, WithoutMotionsOrIntervalPredictsNoMotion) {
  VelocityModel model(0.5);
  EXPECT_TRUE(model.Predict(0.033).isApprox(Pose::Identity()));
  model.Add(1.0, 0.0, Motion(0.1, 0.1));  // no interval: ignored
  EXPECT_TRUE(model.empty());
  model.Add(1.0, 0.033, Motion(0.1, 0.1));
  EXPECT_TRUE(model.Predict(0.0).isApprox(Pose::Identity()));
}

TEST(VelocityModel, ConstantMotionIsPredictedAndScaledToTheInterval) {
  VelocityModel model(0.5);
  for (int i = 1; i <= 10; ++i) model.Add(0.1 * i, 0.1, Motion(0.01, 0.002));
  const Pose same = model.Predict(0.1);
  EXPECT_NEAR(same.translation().x(), 0.01, 1e-12);
  EXPECT_NEAR(BoxMinus(same, Pose::Identity())(5), 0.002, 1e-12);
  // Twice the interval (a dropped frame): twice the motion.
  EXPECT_NEAR(model.Predict(0.2).translation().x(), 0.02, 1e-12);
}

TEST(VelocityModel, OneBadMotionIsAveragedNotHeld) {
  // Ten motions of 1 cm and one wrong by 5 cm: the window's mean is off by 5/11 cm, the last
  // motion alone (window 0) by the whole 5 cm.
  VelocityModel windowed(1.0), last_only(0.0);
  for (int i = 1; i <= 10; ++i) {
    windowed.Add(0.033 * i, 0.033, Motion(0.01, 0.0));
    last_only.Add(0.033 * i, 0.033, Motion(0.01, 0.0));
  }
  windowed.Add(0.033 * 11, 0.033, Motion(0.06, 0.0));
  last_only.Add(0.033 * 11, 0.033, Motion(0.06, 0.0));
  EXPECT_NEAR(windowed.Predict(0.033).translation().x(), 0.01 + 0.05 / 11, 1e-12);
  EXPECT_NEAR(last_only.Predict(0.033).translation().x(), 0.06, 1e-12);
}

TEST(VelocityModel, MotionsOlderThanTheWindowAreForgotten) {
  VelocityModel model(0.25);
  for (int i = 1; i <= 10; ++i) model.Add(0.1 * i, 0.1, Motion(0.01, 0.0));
  for (int i = 11; i <= 13; ++i) model.Add(0.1 * i, 0.1, Motion(0.03, 0.0));
  // The motions ending at 1.1, 1.2 and 1.3 s are within 0.25 s of the latest; the 1 cm ones,
  // which ended at 1.0 s or earlier, are gone.
  EXPECT_NEAR(model.Predict(0.1).translation().x(), 0.03, 1e-12);
}

TEST(VelocityModel, AnUntrustedPartKeepsItsOwnRateWhileTheOtherFollows) {
  VelocityModel model(0.25);
  AddFrames(&model, 1, 10, 0.1, Motion(0.01, 0.002));
  // The turn speeds up while the translation is left to the prior (e.g. two walls only): the
  // rotation follows, the translation keeps its last trusted rate, and even beyond the window
  // (its motions ended 0.3 s before the latest) is not forgotten.
  AddFrames(&model, 11, 13, 0.1, Motion(0.05, 0.006), /*translation_known=*/false);
  const Pose predicted = model.Predict(0.1);
  EXPECT_NEAR(predicted.translation().x(), 0.01, 1e-12);
  EXPECT_NEAR(LogSO3(predicted.linear()).z(), 0.006, 1e-12);
  // And the other way round. The window runs over measured time, so the first translation after
  // the held 0.3 s is averaged with the last measured ones (those of 0.9 and 1.0 s).
  model.Add(1.4, 0.1, Motion(0.02, 0.5), /*translation_known=*/true, /*rotation_known=*/false);
  EXPECT_NEAR(model.Predict(0.1).translation().x(), (0.01 + 0.01 + 0.02) / 3, 1e-12);
  EXPECT_NEAR(LogSO3(model.Predict(0.1).linear()).z(), 0.006, 1e-12);
}

TEST(VelocityModel, ADriftCorrectionIsSpreadOverTheFramesItAccumulatedIn) {
  // 1 cm a frame, then ten frames whose translation the prior held at 1 cm while the sensor
  // moved 1.2 cm: the first measured frame moves 1.2 cm plus the 2 cm the prior fell behind.
  // Taken as one frame's rate that is 3.2 cm; spread over the eleven frames it is 1.2 cm.
  for (const int span : {1, 11}) {
    VelocityModel model(0.0);  // the latest motion alone
    AddFrames(&model, 1, 10, 0.033, Motion(0.01, 0.0));
    AddFrames(&model, 11, 20, 0.033, Motion(0.01, 0.0), /*translation_known=*/false);
    model.Add(0.033 * 21, 0.033, Motion(0.032, 0.0), true, true, span);
    EXPECT_NEAR(model.Predict(0.033).translation().x(), span == 1 ? 0.032 : 0.012, 1e-12);
  }
  // Without a rate to hold, the motion is taken as it is.
  VelocityModel fresh(0.25);
  fresh.Add(0.033, 0.033, Motion(0.02, 0.0), true, true, 5);
  EXPECT_NEAR(fresh.Predict(0.033).translation().x(), 0.02, 1e-12);
}

TEST(VelocityModel, AHeldStretchDoesNotEmptyTheWindow) {
  // Frames every 0.1 s: five of 1 cm, five held, then one wrong by 5 cm. Held time does not
  // count, so the 0.25 s window still holds the motions ending at 0.4 and 0.5 s, and the wrong
  // one is averaged with them rather than becoming the velocity.
  VelocityModel model(0.25);
  AddFrames(&model, 1, 5, 0.1, Motion(0.01, 0.0));
  AddFrames(&model, 6, 10, 0.1, Motion(0.01, 0.0), /*translation_known=*/false);
  model.Add(1.1, 0.1, Motion(0.06, 0.0));
  EXPECT_NEAR(model.Predict(0.1).translation().x(), (0.01 + 0.01 + 0.06) / 3, 1e-12);
  // The rotation, measured throughout, keeps the ordinary window.
  EXPECT_NEAR(LogSO3(model.Predict(0.1).linear()).z(), 0.0, 1e-12);
}

TEST(VelocityModel, AHeldTurnContinuesAlongItsTrend) {
  // The yaw rate grows by 1 rad/s per second; the motion of the frame ending at t covers
  // [t - 0.1, t], so its mean rate is that at t - 0.05. From 1.0 s on the rotation is held (the
  // planes no longer see it): the frame ending at 1.3 s turns at the rate of 1.25 s, which the
  // trend gives exactly, while the window's mean is that of 0.75 s.
  auto rate = [](double t) { return 0.2 + 1.0 * t; };
  VelocityModel model(0.45);
  for (int i = 1; i <= 10; ++i) {
    const double t = 0.1 * i;
    model.Add(t, 0.1, Motion(0.01, 0.1 * rate(t - 0.05)));
  }
  for (int i = 11; i <= 12; ++i) {
    model.Add(0.1 * i, 0.1, Motion(0.01, 0.0), /*translation_known=*/true,
              /*rotation_known=*/false);
  }
  EXPECT_NEAR(LogSO3(model.PredictContinuingHeldTurn(0.1, 1.3).linear()).z(), 0.1 * rate(1.25),
              1e-12);
  EXPECT_NEAR(LogSO3(model.Predict(0.1).linear()).z(), 0.1 * rate(0.75), 1e-12);
  // The continuation goes at most one window beyond the last measured turn.
  EXPECT_NEAR(LogSO3(model.PredictContinuingHeldTurn(0.1, 5.0).linear()).z(),
              LogSO3(model.PredictContinuingHeldTurn(0.1, 1.0 + 0.45 + 0.05).linear()).z(), 1e-12);
  EXPECT_NEAR(LogSO3(model.PredictContinuingHeldTurn(0.1, 5.0).linear()).z(), 0.1 * rate(1.45),
              1e-12);
  // Not held (the last motion ended at the previous frame): the mean, as Predict.
  model.Add(1.3, 0.1, Motion(0.01, 0.1 * rate(1.25)));
  EXPECT_TRUE(model.PredictContinuingHeldTurn(0.1, 1.4).isApprox(model.Predict(0.1), 1e-15));
}

TEST(VelocityModel, AHeldTurnIsNotBentByOneWrongMotion) {
  // A yaw rate growing by 1 rad/s per second, then one motion wrong by 0.05 rad (a plane
  // matched wrongly) just before the rotation is held. The continued turn keeps the trend of the
  // other motions; a least-squares line would take a slope from the outlier at its end.
  auto rate = [](double t) { return 0.2 + 1.0 * t; };
  VelocityModel model(0.45);
  for (int i = 1; i <= 9; ++i) {
    const double t = 0.1 * i;
    model.Add(t, 0.1, Motion(0.01, 0.1 * rate(t - 0.05)));
  }
  model.Add(1.0, 0.1, Motion(0.01, 0.1 * rate(0.95) + 0.05));
  model.Add(1.1, 0.1, Motion(0.01, 0.0), /*translation_known=*/true, /*rotation_known=*/false);
  EXPECT_NEAR(LogSO3(model.PredictContinuingHeldTurn(0.1, 1.2).linear()).z(), 0.1 * rate(1.15),
              1e-12);
}

}  // namespace
}  // namespace planeslam::registration

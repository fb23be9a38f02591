// Trajectory evaluation against hand-computed cases (evo's and the TUM tools' rules, worked out
// from their source), closed-form alignment, invariants, and the TUM tools' published numbers on
// the shared data.
#include "planeslam/datasets/trajectory_eval.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

constexpr double kPi = 3.14159265358979323846;

Pose MakePose(const Eigen::Vector3d& t, double yaw_rad = 0.0,
              const Eigen::Vector3d& axis = Eigen::Vector3d::UnitZ()) {
  Pose p = Pose::Identity();
  p.linear() = Eigen::AngleAxisd(yaw_rad, axis.normalized()).toRotationMatrix();
  p.translation() = t;
  return p;
}

Trajectory RandomWalk(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  Trajectory t;
  Pose p = Pose::Identity();
  for (int i = 0; i < n; ++i) {
    p = p * MakePose(Eigen::Vector3d(0.3 + 0.1 * g(rng), 0.1 * g(rng), 0.1 * g(rng)), 0.1 * g(rng),
                     Eigen::Vector3d(g(rng), g(rng), g(rng)));
    t.Add(100.0 + 0.05 * i, p);
  }
  return t;
}

std::string F6(double v) {
  char b[64];
  std::snprintf(b, sizeof(b), "%.6f", v);
  return b;
}

TEST(Association, EvoNearestFromTheShorterTrajectory) {
  // Estimate shorter: each estimate stamp takes its nearest reference stamp within 0.01 s.
  const std::vector<double> ref{0.0, 0.1, 0.2, 0.3, 0.4}, est{0.005, 0.1049, 0.3, 0.35};
  const std::vector<IndexPair> pairs = AssociateNearest(ref, est, 0.01);
  EXPECT_EQ(pairs, (std::vector<IndexPair>{{0, 0}, {1, 1}, {3, 2}}));  // 0.35 is 0.05 from both
  // Not one to one: both estimate stamps pick reference 1.0 (evo keeps both pairs).
  EXPECT_EQ(AssociateNearest({0.0, 1.0, 2.0}, {0.998, 1.001}, 0.01),
            (std::vector<IndexPair>{{1, 0}, {1, 1}}));
  // Estimate strictly longer: the reference is the short side; an exact tie takes the first.
  EXPECT_EQ(AssociateNearest({1.0}, {0.75, 1.25}, 0.5), (std::vector<IndexPair>{{0, 0}}));
  // max_diff is inclusive (evo: diffs <= max_diff), with exactly representable values.
  EXPECT_EQ(AssociateNearest({1.0, 2.0, 3.0}, {1.5}, 0.5), (std::vector<IndexPair>{{0, 0}}));
  // The offset is added to the estimate's stamps.
  EXPECT_EQ(AssociateNearest({0.0, 0.1, 0.2, 0.3}, {10.0, 10.1, 10.2}, 0.01, -10.0),
            (std::vector<IndexPair>{{0, 0}, {1, 1}, {2, 2}}));
}

TEST(Association, TumClosestFirstOneToOne) {
  // associate.py: 1.001 is closer to 1.0 than 0.998, so it wins; 0.998 has nothing else < 0.02 s.
  EXPECT_EQ(AssociateTum({0.0, 1.0, 2.0}, {0.998, 1.001}, 0.02), (std::vector<IndexPair>{{1, 1}}));
  // Strict: a difference of exactly max_diff is not a match (0.5 exact in binary).
  EXPECT_TRUE(AssociateTum({1.0}, {1.5}, 0.5).empty());
  // Greedy by difference: est 0.51 would prefer ref 0.5 but ref 0.5 goes to est 0.505 first.
  EXPECT_EQ(AssociateTum({0.5, 0.52}, {0.505, 0.51}, 0.02),
            (std::vector<IndexPair>{{0, 0}, {1, 1}}));
}

TEST(Association, NoOverlapIsAnIoErrorNamingTheEstimate) {
  Trajectory ref, est;
  for (int i = 0; i < 5; ++i) {
    ref.Add(i * 0.1, Pose::Identity());
    est.Add(100.0 + i * 0.1, Pose::Identity());
  }
  try {
    AssociateTrajectories(ref, est, AssociationOptions{}, "gt.txt", "est.txt");
    FAIL() << "no exception";
  } catch (const IoError& e) {
    EXPECT_EQ(e.file(), "est.txt");
    EXPECT_EQ(std::string(e.what()).rfind("est.txt: no timestamps within 0.01 s of gt.txt", 0), 0u)
        << e.what();
  }
  AssociationOptions by_index;
  by_index.method = AssociationOptions::Method::kIndex;
  est.Add(200.0, Pose::Identity());
  EXPECT_THROW(AssociateTrajectories(ref, est, by_index), IoError);
}

TEST(Umeyama, RecoversAKnownSim3AndSe3) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-5.0, 5.0);
  Eigen::Matrix3Xd x(3, 200);
  for (int i = 0; i < x.cols(); ++i) x.col(i) = Eigen::Vector3d(u(rng), u(rng), u(rng));
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(2.7, Eigen::Vector3d(0.3, -0.5, 0.8).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(1.5, -2.0, 30.0);
  for (double s : {1.0, 2.5, 0.01}) {
    const Eigen::Matrix3Xd y = ((s * r) * x).colwise() + t;
    const UmeyamaResult fit = UmeyamaAlignment(x, y, /*with_scale=*/s != 1.0);
    ASSERT_FALSE(fit.degenerate);
    EXPECT_LT((fit.transform.rotation - r).norm(), 1e-9) << "s " << s;
    EXPECT_LT((fit.transform.translation - t).norm(), 1e-9) << "s " << s;
    EXPECT_NEAR(fit.transform.scale, s, 1e-9);
  }
}

TEST(Umeyama, DegenerateInputsAreFlagged) {
  Eigen::Matrix3Xd line(3, 10);
  for (int i = 0; i < 10; ++i)
    line.col(i) = Eigen::Vector3d(1, 2, 3) * i + Eigen::Vector3d(5, 0, 0);
  const UmeyamaResult collinear = UmeyamaAlignment(line, line, false);
  EXPECT_TRUE(collinear.degenerate);
  EXPECT_NE(collinear.reason.find("collinear"), std::string::npos);
  const UmeyamaResult two = UmeyamaAlignment(line.leftCols(2), line.leftCols(2), true);
  EXPECT_TRUE(two.degenerate);
  EXPECT_NE(two.reason.find("at least 3"), std::string::npos);
  // A degenerate alignment leaves the estimate untouched and the APE result says why.
  std::vector<Pose> ref, est;
  for (int i = 0; i < 10; ++i) {
    ref.push_back(MakePose(line.col(i)));
    est.push_back(MakePose(2.0 * line.col(i)));
  }
  const std::vector<Pose> before = est;
  AlignmentOptions a;
  a.align = true;
  EXPECT_TRUE(AlignTrajectory(ref, est, a).degenerate);
  EXPECT_TRUE(est[3].isApprox(before[3]));
}

TEST(Alignment, Sim3ScaleOnlyAndOriginAsEvo) {
  const Trajectory ref = RandomWalk(60, 3);
  // est = S * ref for a known Sim(3) S: Sim(3) alignment brings APE to zero.
  const Eigen::Matrix3d r = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitY()).toRotationMatrix();
  std::vector<Pose> est_sim, est_scaled, est_rigid;
  const Pose rigid = MakePose(Eigen::Vector3d(3, -1, 2), 1.1, Eigen::Vector3d(1, 1, 0));
  for (const Pose& p : ref.poses) {
    Pose q = p;
    q.translation() = 0.4 * (r * p.translation()) + Eigen::Vector3d(1, 2, 3);
    q.linear() = r * p.linear();
    est_sim.push_back(q);
    Pose s = p;
    s.translation() *= 3.0;
    est_scaled.push_back(s);
    est_rigid.push_back(rigid * p);
  }
  AlignmentOptions sim3;
  sim3.align = sim3.correct_scale = true;
  const AlignmentResult a = AlignTrajectory(ref.poses, est_sim, sim3);
  EXPECT_NEAR(a.umeyama.scale, 2.5, 1e-9);
  EXPECT_LT(ComputeStatistics(ApeErrors(ref.poses, est_sim, PoseRelation::kFull)).max, 1e-9);
  // evo -s: only the scale of the Sim(3) fit, about the origin.
  AlignmentOptions scale_only;
  scale_only.correct_scale = true;
  const AlignmentResult b = AlignTrajectory(ref.poses, est_scaled, scale_only);
  EXPECT_NEAR(b.umeyama.scale, 1.0 / 3.0, 1e-12);
  EXPECT_TRUE(b.umeyama.rotation.isIdentity());
  EXPECT_LT(ComputeStatistics(ApeErrors(ref.poses, est_scaled, PoseRelation::kTranslation)).max,
            1e-12);
  // --align-origin: a rigidly moved copy coincides after moving its first pose.
  AlignmentOptions origin;
  origin.align_origin = true;
  AlignTrajectory(ref.poses, est_rigid, origin);
  EXPECT_LT(ComputeStatistics(ApeErrors(ref.poses, est_rigid, PoseRelation::kFull)).max, 1e-12);
}

TEST(Alignment, ApeScaleMultipliesEstimatePositionsFirst) {
  // evaluate_ate.py --scale: an estimate at half scale is exact once multiplied by 2.
  Trajectory ref = RandomWalk(30, 5), est = ref;
  for (Pose& p : est.poses) p.translation() *= 0.5;
  ApeOptions o;
  o.scale = 2.0;
  const ApeResult r = EvaluateApe(ref, est, o);
  ASSERT_TRUE(r.ok);
  EXPECT_EQ(r.stats.count, 30u);
  EXPECT_LT(r.stats.max, 1e-12);
}

TEST(Alignment, NToAlignUsesOnlyTheFirstPairs) {
  const Trajectory ref = RandomWalk(40, 4);
  std::vector<Pose> est = ref.poses;
  const Pose moved = MakePose(Eigen::Vector3d(1, 2, 3), 0.5);
  for (std::size_t i = 20; i < est.size(); ++i) est[i] = moved * est[i];  // second half drifts
  AlignmentOptions a;
  a.align = true;
  a.n_to_align = 20;
  AlignTrajectory(ref.poses, est, a);
  const std::vector<double> e = ApeErrors(ref.poses, est, PoseRelation::kTranslation);
  for (int i = 0; i < 20; ++i) EXPECT_LT(e[i], 1e-9);
  EXPECT_GT(e[30], 0.1);
}

TEST(Statistics, HandComputed) {
  const ErrorStatistics s = ComputeStatistics({4.0, 1.0, 3.0, 2.0});
  EXPECT_EQ(s.count, 4u);
  EXPECT_DOUBLE_EQ(s.sse, 30.0);
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(7.5));
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);           // numpy: mean of the middle two
  EXPECT_DOUBLE_EQ(s.std, std::sqrt(1.25));  // population, ddof 0
  EXPECT_EQ(s.min, 1.0);
  EXPECT_EQ(s.max, 4.0);
  EXPECT_DOUBLE_EQ(ComputeStatistics({3.0, 1.0, 2.0}).median, 2.0);
}

TEST(Ape, PoseRelationsHandComputed) {
  const double theta = 10.0 * kPi / 180.0;
  const std::vector<Pose> ref{Pose::Identity()};
  const std::vector<Pose> est{MakePose(Eigen::Vector3d(0.3, 0.4, 0.0), theta)};
  EXPECT_NEAR(ApeErrors(ref, est, PoseRelation::kTranslation)[0], 0.5, 1e-15);
  EXPECT_NEAR(ApeErrors(ref, est, PoseRelation::kRotationAngleDeg)[0], 10.0, 1e-12);
  EXPECT_NEAR(ApeErrors(ref, est, PoseRelation::kRotationAngleRad)[0], theta, 1e-15);
  // ‖Rz(θ) - I‖_F² = 4 (1 - cos θ); E = est⁻¹ ref has |t_E| = 0.5.
  EXPECT_NEAR(ApeErrors(ref, est, PoseRelation::kRotationPart)[0],
              std::sqrt(4.0 * (1.0 - std::cos(theta))), 1e-15);
  EXPECT_NEAR(ApeErrors(ref, est, PoseRelation::kFull)[0],
              std::sqrt(4.0 * (1.0 - std::cos(theta)) + 0.25), 1e-15);
  // The angle is accurate near 0 and pi, where acos is not.
  EXPECT_NEAR(RotationAngle(Eigen::AngleAxisd(1e-9, Eigen::Vector3d::UnitX()).toRotationMatrix()),
              1e-9, 1e-20);
  EXPECT_NEAR(
      RotationAngle(Eigen::AngleAxisd(kPi - 1e-9, Eigen::Vector3d::UnitY()).toRotationMatrix()),
      kPi - 1e-9, 1e-15);
}

TEST(Rpe, EvoPairSelectionHandComputed) {
  std::vector<Pose> poses;
  for (int i = 0; i < 10; ++i) poses.push_back(MakePose(Eigen::Vector3d(0.4 * i, 0, 0), 0.0));
  EXPECT_EQ(EvoRpePairs(std::vector<Pose>(poses.begin(), poses.begin() + 7), 2, DeltaUnit::kFrames),
            (std::vector<IndexPair>{{0, 2}, {2, 4}, {4, 6}}));
  EXPECT_EQ(EvoRpePairs(std::vector<Pose>(poses.begin(), poses.begin() + 7), 2, DeltaUnit::kFrames,
                        0.1, /*all_pairs=*/true),
            (std::vector<IndexPair>{{0, 2}, {1, 3}, {2, 4}, {3, 5}, {4, 6}}));
  // Path: 0.4 m steps, delta 1 m; evo's first pair starts where 1 m was first reached (index 3).
  EXPECT_EQ(EvoRpePairs(poses, 1.0, DeltaUnit::kMeters), (std::vector<IndexPair>{{3, 6}, {6, 9}}));
  // All pairs by path: nearest accumulated distance to 1.2 m within 10 %: j = i + 3.
  const std::vector<IndexPair> all = EvoRpePairs(poses, 1.2, DeltaUnit::kMeters, 0.1, true);
  ASSERT_EQ(all.size(), 7u);
  EXPECT_EQ(all.front(), IndexPair(0, 3));
  EXPECT_EQ(all.back(), IndexPair(6, 9));
  // Angles: 6 degrees a step, delta 10 degrees: pairs every 2 steps starting at 0.
  std::vector<Pose> turning;
  for (int i = 0; i < 7; ++i)
    turning.push_back(MakePose(Eigen::Vector3d::Zero(), i * 6.0 * kPi / 180));
  EXPECT_EQ(EvoRpePairs(turning, 10.0, DeltaUnit::kDegrees),
            (std::vector<IndexPair>{{0, 2}, {2, 4}, {4, 6}}));
  EXPECT_EQ(EvoRpePairs(turning, 12.0 * kPi / 180, DeltaUnit::kRadians, 0.1, true).size(), 5u);
}

TEST(Rpe, EvoAndTumErrorFormsDifferUnderRotation) {
  // Q_i = I, Q_j = translate (1, 0, 0); P_i = I, P_j = [Rz(90°) | (1, 0, 0)].
  const Pose qi = Pose::Identity(), qj = MakePose(Eigen::Vector3d(1, 0, 0));
  const Pose pi = Pose::Identity(), pj = MakePose(Eigen::Vector3d(1, 0, 0), kPi / 2);
  // evo: inv(Q_rel) P_rel = [Rz(90°) | 0].
  const Pose e_evo = EvoRelativeError(qi, qj, pi, pj);
  EXPECT_NEAR(e_evo.translation().norm(), 0.0, 1e-15);
  EXPECT_NEAR(RotationAngle(e_evo.linear()), kPi / 2, 1e-15);
  // TUM: inv(P_j⁻¹ P_i) (Q_j⁻¹ Q_i) = P_j [I | (-1, 0, 0)] = [Rz(90°) | (1, -1, 0)].
  const Pose e_tum = TumRelativeError(qi, qj, pi, pj);
  EXPECT_LT((e_tum.translation() - Eigen::Vector3d(1, -1, 0)).norm(), 1e-15);
  EXPECT_NEAR(RotationAngle(e_tum.linear()), kPi / 2, 1e-15);
}

TEST(Rpe, EvoDriftAndSe3Invariance) {
  // Reference steps 1 m along x, the estimate 1.1 m: every consecutive pair is 0.1 m off.
  Trajectory ref, est;
  for (int i = 0; i < 20; ++i) {
    ref.Add(i * 0.1, MakePose(Eigen::Vector3d(1.0 * i, 0, 0)));
    est.Add(i * 0.1, MakePose(Eigen::Vector3d(1.1 * i, 0, 0)));
  }
  RpeOptions o;
  const RpeResult r = EvaluateRpe(ref, est, o);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.stats.count, 19u);
  EXPECT_NEAR(r.stats.rmse, 0.1, 1e-12);
  EXPECT_NEAR(r.stats.std, 0.0, 1e-12);
  // RPE does not change when the estimate is moved rigidly (random walk, any relation).
  const Trajectory walk = RandomWalk(80, 9);
  Trajectory noisy = walk, moved;
  std::mt19937 rng(1);
  std::normal_distribution<double> g(0.0, 0.01);
  for (Pose& p : noisy.poses) p = p * MakePose(Eigen::Vector3d(g(rng), g(rng), g(rng)), g(rng));
  const Pose t = MakePose(Eigen::Vector3d(5, -3, 1), 2.0, Eigen::Vector3d(1, 2, 3));
  moved = noisy;
  for (Pose& p : moved.poses) p = t * p;
  o.relation = PoseRelation::kFull;
  o.delta = 3;
  const RpeResult a = EvaluateRpe(walk, noisy, o), b = EvaluateRpe(walk, moved, o);
  ASSERT_TRUE(a.ok && b.ok);
  ASSERT_EQ(a.errors.size(), b.errors.size());
  for (std::size_t i = 0; i < a.errors.size(); ++i) EXPECT_NEAR(a.errors[i], b.errors[i], 1e-12);
}

TEST(Rpe, TumFindClosestIndexAsTheScript) {
  const std::vector<double> l{0, 1, 2, 3, 4, 5};
  EXPECT_EQ(TumFindClosestIndex(l, 2.4), 2u);
  EXPECT_EQ(TumFindClosestIndex(l, 2.6), 3u);
  EXPECT_EQ(TumFindClosestIndex(l, 3.0), 3u);
  EXPECT_EQ(TumFindClosestIndex(l, -5.0), 0u);
  EXPECT_EQ(TumFindClosestIndex(l, 10.0), 5u);
}

// The TUM benchmark's published numbers for the shared files (data README), to the printed digit.
class TumReference : public ::testing::Test {
 protected:
  static Trajectory Read(const std::string& name) {
    TrajectoryReadOptions o;
    o.duplicates = TrajectoryReadOptions::Duplicates::kKeepLast;  // a Python dict, as the tools
    return ReadTumTrajectory((test::DataDir() / "trajectories" / name).string(), nullptr, o);
  }
  static ApeResult Ate(const std::string& gt, const std::string& est) {
    ApeOptions o;
    o.association.method = AssociationOptions::Method::kTum;
    o.association.max_diff = 0.02;
    o.alignment.align = true;  // evaluate_ate.py always aligns (Horn)
    return EvaluateApe(Read(gt), Read(est), o);
  }
};

TEST_F(TumReference, AteFreiburg1XyzRgbdslam) {
  PLANESLAM_REQUIRE_DATA();
  const ApeResult r = Ate("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt");
  ASSERT_TRUE(r.ok);
  EXPECT_EQ(r.stats.count, 786u);
  EXPECT_EQ(F6(r.stats.rmse), "0.013473");
  EXPECT_EQ(F6(r.stats.mean), "0.012029");
  EXPECT_EQ(F6(r.stats.median), "0.011176");
  EXPECT_EQ(F6(r.stats.std), "0.006068");
  EXPECT_EQ(F6(r.stats.min), "0.000939");
  EXPECT_EQ(F6(r.stats.max), "0.034727");
}

TEST_F(TumReference, AteFr2DeskOrb) {
  PLANESLAM_REQUIRE_DATA();
  const ApeResult r = Ate("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt");
  ASSERT_TRUE(r.ok);
  EXPECT_EQ(r.stats.count, 2223u);
  EXPECT_EQ(F6(r.stats.rmse), "0.008144");
  EXPECT_EQ(F6(r.stats.mean), "0.007514");
  EXPECT_EQ(F6(r.stats.median), "0.007432");
  EXPECT_EQ(F6(r.stats.std), "0.003140");
  EXPECT_EQ(F6(r.stats.min), "0.000332");
  EXPECT_EQ(F6(r.stats.max), "0.024329");
}

TEST_F(TumReference, RpeFreiburg1XyzFixedDeltaOneSecond) {
  PLANESLAM_REQUIRE_DATA();
  RpeOptions o;
  o.tum = true;
  o.fixed_delta = true;
  o.delta = 1.0;
  o.delta_unit = DeltaUnit::kSeconds;
  const RpeResult r =
      EvaluateRpe(Read("freiburg1_xyz-groundtruth.txt"), Read("freiburg1_xyz-rgbdslam.txt"), o);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.trans_stats.count, 753u);
  EXPECT_EQ(F6(r.trans_stats.rmse), "0.021217");
  EXPECT_EQ(F6(r.trans_stats.mean), "0.019524");
  EXPECT_EQ(F6(r.rot_stats_deg.rmse), "0.934480");
  EXPECT_EQ(F6(r.rot_stats_deg.mean), "0.841472");
  // The selected relation (translation) is what `errors` holds.
  EXPECT_EQ(r.stats.rmse, r.trans_stats.rmse);
}

}  // namespace
}  // namespace planeslam::datasets

// Trajectory readers and writers: round trips, format detection, and one-line errors naming the
// file and line for the inputs users get wrong.
#include "planeslam/datasets/trajectory_io.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <random>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

std::string WriteText(const std::filesystem::path& dir, const std::string& name,
                      const std::string& text) {
  const std::string path = (dir / name).string();
  std::ofstream(path) << text;
  return path;
}

Trajectory RandomTrajectory(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  Trajectory t;
  double stamp = 1305031102.160407;
  for (int i = 0; i < n; ++i) {
    Pose p = Pose::Identity();
    p.linear() = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    p.translation() = Eigen::Vector3d(u(rng), u(rng), u(rng));
    stamp += 0.0331 + 0.001 * u(rng);
    t.Add(stamp, p);
  }
  return t;
}

/// The IoError message of `fn`, or "" when it does not throw.
template <typename F>
std::string ErrorOf(F fn) {
  try {
    fn();
  } catch (const IoError& e) {
    return e.what();
  }
  return "";
}

TEST(TrajectoryIo, TumRoundTripIsBitExact) {
  const auto dir = test::ScratchDir();
  const Trajectory t = RandomTrajectory(50, 1);
  const std::string path = (dir / "traj.txt").string();
  WriteTumTrajectory(path, t);
  const Trajectory back = ReadTumTrajectory(path);
  ASSERT_EQ(back.size(), t.size());
  for (std::size_t i = 0; i < t.size(); ++i) {
    EXPECT_EQ(back.stamps[i], t.stamps[i]);
    EXPECT_EQ(back.poses[i].translation(), t.poses[i].translation());
    // A rotation goes through a quaternion and back: equal to a few ulps of its entries.
    EXPECT_LT((back.poses[i].linear() - t.poses[i].linear()).norm(), 8 * 2.2e-16);
  }
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp." + std::to_string(::getpid())));
}

TEST(TrajectoryIo, KittiRoundTripWithTimes) {
  const auto dir = test::ScratchDir();
  const Trajectory t = RandomTrajectory(20, 2);
  const std::string path = (dir / "poses.txt").string(), times = (dir / "times.txt").string();
  WriteKittiTrajectory(path, t, times);
  const Trajectory back = ReadKittiTrajectory(path, times);
  ASSERT_EQ(back.size(), t.size());
  for (std::size_t i = 0; i < t.size(); ++i) {
    EXPECT_EQ(back.stamps[i], t.stamps[i]);
    EXPECT_EQ(back.poses[i].matrix(), t.poses[i].matrix());  // 12 numbers kept exactly
  }
  // Without a times file the stamps are the frame indices.
  const Trajectory no_times = ReadKittiTrajectory(path);
  EXPECT_EQ(no_times.stamps[7], 7.0);
  EXPECT_EQ(DetectTrajectoryFormat(path), TrajectoryFormat::kKitti);
}

TEST(TrajectoryIo, EurocCsvNanosecondsAndWFirst) {
  const auto dir = test::ScratchDir();
  // A 90 degree turn about z: q = (w, x, y, z) = (cos 45, 0, 0, sin 45); extra columns ignored.
  const std::string path = WriteText(
      dir, "data.csv",
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], "
      "q_RS_z [], v_RS_R_x [m s^-1]\n"
      "1403636579758555392,4.688,-1.786,0.783,0.7071067811865476,0,0,0.7071067811865476,0.1\n"
      "1403636579763555584,4.688,-1.786,0.787,1,0,0,0,0.1\n");
  EXPECT_EQ(DetectTrajectoryFormat(path), TrajectoryFormat::kEuroc);
  const Trajectory t = ReadEurocTrajectory(path);
  ASSERT_EQ(t.size(), 2u);
  EXPECT_DOUBLE_EQ(t.stamps[0], 1403636579758555392.0 / 1e9);
  EXPECT_NEAR(t.stamps[1] - t.stamps[0], 0.005, 1e-6);
  EXPECT_NEAR((t.poses[0].linear() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(),
              0.0, 1e-12);
  EXPECT_EQ(t.poses[1].translation(), Eigen::Vector3d(4.688, -1.786, 0.787));
}

TEST(TrajectoryIo, DetectsTumAndRefusesUnknownLayouts) {
  const auto dir = test::ScratchDir();
  const std::string tum = WriteText(dir, "a.txt", "# c\n\n1 0 0 0 0 0 0 1\n");
  EXPECT_EQ(DetectTrajectoryFormat(tum), TrajectoryFormat::kTum);
  const std::string odd = WriteText(dir, "b.txt", "# c\n1 2 3 4 5\n");
  EXPECT_EQ(ErrorOf([&] { DetectTrajectoryFormat(odd); }),
            odd +
                ":2: cannot detect the format: 5 columns (TUM has 8, KITTI 12, EuRoC is "
                "comma-separated); use --format");
}

TEST(TrajectoryIo, SevenColumnsNamesFileAndLine) {
  const auto dir = test::ScratchDir();
  const std::string path =
      WriteText(dir, "t.txt", "# header\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n");
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(path); }),
            path + ":3: expected 8 columns 't tx ty tz qx qy qz qw' (TUM), got 7 columns");
}

TEST(TrajectoryIo, TextInANumberNamesColumn) {
  const auto dir = test::ScratchDir();
  const std::string path = WriteText(dir, "t.txt", "1.0 0 0 0 0 0 0 1\n2.0 0 0.5x 0 0 0 0 1\n");
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(path); }),
            path + ":2: column 3: '0.5x' is not a number");
  const std::string nan = WriteText(dir, "n.txt", "1.0 nan 0 0 0 0 0 1\n");
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(nan); }), nan + ":1: column 2: 'nan' is not finite");
}

TEST(TrajectoryIo, UnsortedAndDuplicateStamps) {
  const auto dir = test::ScratchDir();
  const std::string unsorted =
      WriteText(dir, "u.txt", "1.5 0 0 0 0 0 0 1\n2.5 0 0 0 0 0 0 1\n2.25 0 0 0 0 0 0 1\n");
  EXPECT_EQ(
      ErrorOf([&] { ReadTumTrajectory(unsorted); }),
      unsorted + ":3: timestamp 2.25 is before the previous one (2.5): stamps must be sorted");
  const std::string dup =
      WriteText(dir, "d.txt", "1.5 0 0 0 0 0 0 1\n2.5 1 0 0 0 0 0 1\n2.5 2 0 0 0 0 0 1\n");
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(dup); }),
            dup + ":3: duplicate timestamp 2.5 (stamps must be unique)");
  // The tools' behaviours on request, with a warning naming the line.
  TrajectoryReadOptions last;
  last.duplicates = TrajectoryReadOptions::Duplicates::kKeepLast;
  TrajectoryReadReport report;
  const Trajectory kept_last = ReadTumTrajectory(dup, &report, last);
  ASSERT_EQ(kept_last.size(), 2u);
  EXPECT_EQ(kept_last.poses[1].translation().x(), 2.0);
  ASSERT_EQ(report.warnings.size(), 1u);
  EXPECT_NE(report.warnings[0].find("(line 3)"), std::string::npos);
  TrajectoryReadOptions first;
  first.duplicates = TrajectoryReadOptions::Duplicates::kKeepFirst;
  EXPECT_EQ(ReadTumTrajectory(dup, nullptr, first).poses[1].translation().x(), 1.0);
}

TEST(TrajectoryIo, QuaternionNormsRoundingWarningRefusal) {
  const auto dir = test::ScratchDir();
  // 4-decimal rounding (as TUM ground truth): silent.
  const std::string rounded = WriteText(dir, "r.txt", "1 0 0 0 0.6132 0.5962 -0.3311 -0.3986\n");
  TrajectoryReadReport report;
  const Trajectory t = ReadTumTrajectory(rounded, &report);
  EXPECT_TRUE(report.warnings.empty());
  EXPECT_NEAR(
      (t.poses[0].linear().transpose() * t.poses[0].linear() - Eigen::Matrix3d::Identity()).norm(),
      0.0, 1e-14);
  // Norm 1.01: normalised, with a warning.
  const std::string off = WriteText(dir, "o.txt", "1 0 0 0 0 0 0 1.01\n");
  const Trajectory o = ReadTumTrajectory(off, &report);
  ASSERT_EQ(report.warnings.size(), 1u);
  EXPECT_NE(report.warnings[0].find("1 quaternion(s)"), std::string::npos);
  EXPECT_NEAR((o.poses[0].linear() - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-15);
  // Norm 2: refused.
  const std::string bad = WriteText(dir, "b.txt", "1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 2\n");
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(bad); }),
            bad + ":2: quaternion norm 2 is not 1 (tolerance 0.05)");
}

TEST(TrajectoryIo, KittiErrors) {
  const auto dir = test::ScratchDir();
  const std::string eleven = WriteText(dir, "k.txt", "1 0 0 0 0 1 0 0 0 0 1\n");
  EXPECT_EQ(ErrorOf([&] { ReadKittiTrajectory(eleven); }),
            eleven + ":1: expected 12 columns (KITTI 3x4 [R|t] row-major), got 11 columns");
  const std::string scaled = WriteText(dir, "s.txt", "2 0 0 0 0 2 0 0 0 0 2 0\n");
  EXPECT_NE(ErrorOf([&] { ReadKittiTrajectory(scaled); }).find(scaled + ":1: rotation is not"),
            std::string::npos);
  const std::string ok =
      WriteText(dir, "ok.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n");
  const std::string times = WriteText(dir, "times.txt", "0.0\n");
  EXPECT_NE(ErrorOf([&] { ReadKittiTrajectory(ok, times); }).find(times), std::string::npos);
}

TEST(TrajectoryIo, EmptyAndMissingFiles) {
  const auto dir = test::ScratchDir();
  const std::string empty = WriteText(dir, "e.txt", "# only a comment\n");
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(empty); }), empty + ": no poses in file");
  const std::string missing = (dir / "missing.txt").string();
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(missing); }), missing + ": cannot open file");
}

TEST(TrajectoryIo, ReadsTheSharedTumFiles) {
  PLANESLAM_REQUIRE_DATA();
  const std::string dir = (test::DataDir() / "trajectories").string();
  const Trajectory gt = ReadTumTrajectory(dir + "/freiburg1_xyz-groundtruth.txt");
  const Trajectory est = ReadTumTrajectory(dir + "/freiburg1_xyz-rgbdslam.txt");
  EXPECT_EQ(gt.size(), 3000u);  // 3003 lines, 3 comments
  EXPECT_EQ(est.size(), 788u);
  EXPECT_EQ(gt.stamps.front(), 1305031098.6659);
  EXPECT_EQ(est.poses.front().translation(), Eigen::Vector3d(1.344379, 0.627206, 1.661754));
  // fr2/desk's ground truth repeats one stamp (line 10863): an error unless a policy is chosen.
  EXPECT_EQ(ErrorOf([&] { ReadTumTrajectory(dir + "/fr2_desk_groundtruth.txt"); }),
            dir +
                "/fr2_desk_groundtruth.txt:10863: duplicate timestamp 1311868229.576 (stamps "
                "must be unique)");
}

}  // namespace
}  // namespace planeslam::datasets

#include "planeslam/detection/plane_moments.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "fast_moments.hpp"  // private to detection (detection/src)
#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/plane_covariance.hpp"

namespace planeslam::detection {
namespace {

std::vector<Eigen::Vector3d> NoisyPlanePoints(int n, unsigned seed, double noise,
                                              const Eigen::Vector3d& normal, double d) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::normal_distribution<double> gauss(0.0, noise);
  const Eigen::Vector3d nn = normal.normalized();
  const Eigen::Vector3d a = nn.unitOrthogonal(), b = nn.cross(a);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < n; ++i) {
    pts.push_back(nn * (d + (noise > 0 ? gauss(rng) : 0.0)) + 1.5 * uni(rng) * a +
                  0.7 * uni(rng) * b);
  }
  return pts;
}

/// The batch kernels this CPU runs: the baseline one, and AVX2 where present.
std::vector<SimdKernel> KernelsOfThisCpu() {
  std::vector<SimdKernel> kernels = {SimdKernel::kScalar};
  if (FastestSimdKernel() == SimdKernel::kAvx2) kernels.push_back(SimdKernel::kAvx2);
  return kernels;
}

double RelDiff(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).norm() / std::max(1e-300, b.norm());
}

TEST(PlaneMoments, MergeEqualsMomentsOfUnion) {
  const auto p1 = NoisyPlanePoints(500, 1, 0.01, Eigen::Vector3d(0.2, 0.3, 1), 3.0);
  const auto p2 = NoisyPlanePoints(300, 2, 0.02, Eigen::Vector3d(1, 0, 0.1), 10.0);
  PlaneMoments a, b, all;
  for (const auto& p : p1) a.Add(p);
  for (const auto& p : p2) b.Add(p);
  for (const auto& p : p1) all.Add(p);
  for (const auto& p : p2) all.Add(p);
  PlaneMoments merged = a;
  merged.Merge(b);
  EXPECT_EQ(merged.count(), all.count());
  EXPECT_LT(RelDiff(merged.Centroid(), all.Centroid()), 1e-9);
  EXPECT_LT(RelDiff(merged.Scatter(), all.Scatter()), 1e-9);
  // The flat sums agree with PlaneMoments and merge the same way.
  MomentSums sa, sb, sall;
  for (const auto& p : p1) sa.Add(p.x(), p.y(), p.z(), 0.0);
  for (const auto& p : p2) sb.Add(p.x(), p.y(), p.z(), 0.0);
  for (const auto& p : p1) sall.Add(p.x(), p.y(), p.z(), 0.0);
  for (const auto& p : p2) sall.Add(p.x(), p.y(), p.z(), 0.0);
  sa.Merge(sb);
  double ca[6], call[6];
  sa.Scatter(ca);
  sall.Scatter(call);
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(ca[i], call[i], 1e-9 * std::abs(call[0]));
  EXPECT_LT(RelDiff(sa.ToPlaneMoments().Scatter(), all.Scatter()), 1e-9);
}

TEST(PlaneMoments, FitRecoversExactPlaneAndMseIsEigenvalueOverK) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.2, 1).normalized();
  const auto pts = NoisyPlanePoints(1000, 3, 0.0, n, 2.5);
  PlaneMoments m;
  for (const auto& p : pts) m.Add(p);
  const PlaneFit fit = m.Fit();
  ASSERT_TRUE(fit.valid);
  EXPECT_NEAR(fit.normal.dot(n), 1.0, 1e-12);
  EXPECT_NEAR(fit.d, 2.5, 1e-12);
  EXPECT_NEAR(fit.mse, 0.0, 1e-14);
  // Noisy: MSE = lambda_min / K equals the mean squared residual of eq. (1).
  const auto noisy = NoisyPlanePoints(1000, 4, 0.01, n, 2.5);
  PlaneMoments mn;
  for (const auto& p : noisy) mn.Add(p);
  const PlaneFit f2 = mn.Fit();
  double sq = 0;
  for (const auto& p : noisy) sq += std::pow(f2.normal.dot(p) - f2.d, 2);
  EXPECT_NEAR(f2.mse, sq / noisy.size(), 1e-12);
  EXPECT_NEAR(std::sqrt(f2.mse), 0.01, 0.001);
}

TEST(FastMoments, EigenSolverMatchesEigen) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uni(-1, 1);
  for (int trial = 0; trial < 2000; ++trial) {
    Eigen::Matrix3d a = Eigen::Matrix3d::NullaryExpr([&] { return uni(rng); });
    Eigen::Matrix3d c = a * a.transpose();
    if (trial % 3 == 0) {  // plane-like: one tiny eigenvalue
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
      Eigen::Vector3d ev = es.eigenvalues();
      ev(0) = ev(2) * 1e-9;
      c = es.eigenvectors() * ev.asDiagonal() * es.eigenvectors().transpose();
    }
    const double u[6] = {c(0, 0), c(0, 1), c(0, 2), c(1, 1), c(1, 2), c(2, 2)};
    const SymEigen3 e = SymEigen3Smallest(u);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ref(c);
    const double scale = ref.eigenvalues()(2);
    EXPECT_NEAR(e.l1, ref.eigenvalues()(0), 1e-9 * scale);
    EXPECT_NEAR(e.l2, ref.eigenvalues()(1), 1e-9 * scale);
    EXPECT_NEAR(e.l3, ref.eigenvalues()(2), 1e-9 * scale);
    const double gap = ref.eigenvalues()(1) - ref.eigenvalues()(0);
    if (gap > 1e-3 * scale) {
      EXPECT_NEAR(std::abs(e.v1.dot(ref.eigenvectors().col(0))), 1.0, 1e-8);
    }
  }
}

TEST(FastMoments, BatchEigenvaluesMatchEigenOrDeferToTheClosedForm) {
  // Plane-like (one tiny eigenvalue), general, two equal eigenvalues (Newton cannot separate
  // them), and rank-deficient or empty matrices: every usable lane matches Eigen's solver, the
  // plane-like ones are all usable, and no lane is NaN.
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> uni(-1, 1);
  constexpr int kCount = 1000;
  std::vector<double> columns[6];
  std::vector<Eigen::Matrix3d> matrices;
  for (int i = 0; i < kCount; ++i) {
    const Eigen::Matrix3d a = Eigen::Matrix3d::NullaryExpr([&] { return uni(rng); });
    Eigen::Matrix3d c = a * a.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
    Eigen::Vector3d ev = es.eigenvalues();
    if (i % 4 == 0) ev(0) = ev(2) * 1e-9;  // plane-like
    if (i % 4 == 1) ev(1) = ev(0);         // a double smallest eigenvalue
    if (i % 50 == 2) ev.setZero();         // no points
    if (i % 50 == 3) ev(0) = ev(1) = 0.0;  // points on a line
    c = es.eigenvectors() * ev.asDiagonal() * es.eigenvectors().transpose();
    matrices.push_back(c);
    const double u[6] = {c(0, 0), c(0, 1), c(0, 2), c(1, 1), c(1, 2), c(2, 2)};
    for (int j = 0; j < 6; ++j) columns[j].push_back(u[j]);
  }
  const double* c[6];
  for (int j = 0; j < 6; ++j) c[j] = columns[j].data();
  const std::vector<SimdKernel> kernels = KernelsOfThisCpu();
  for (SimdKernel kernel : kernels) {
    SCOPED_TRACE(::testing::Message() << "kernel " << static_cast<int>(kernel));
    std::vector<double> l1(kCount), l2(kCount), l3(kCount), ok(kCount);
    SymEigenvaluesNewtonBatch(c, kCount, 1e-9, l1.data(), l2.data(), l3.data(), ok.data(), kernel);
    int usable = 0;
    for (int i = 0; i < kCount; ++i) {
      ASSERT_TRUE(ok[i] == 0.0 || ok[i] == 1.0) << i;
      if (i % 4 == 0 && i % 50 != 2) {
        EXPECT_EQ(ok[i], 1.0) << "plane-like matrix " << i;
      }
      if (ok[i] == 0.0) continue;
      ++usable;
      ASSERT_TRUE(std::isfinite(l1[i]) && std::isfinite(l2[i]) && std::isfinite(l3[i])) << i;
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ref(matrices[i]);
      const double scale = ref.eigenvalues()(2);
      EXPECT_NEAR(l1[i], ref.eigenvalues()(0), 1e-9 * scale) << i;
      EXPECT_NEAR(l2[i], ref.eigenvalues()(1), 1e-9 * scale) << i;
      EXPECT_NEAR(l3[i], ref.eigenvalues()(2), 1e-9 * scale) << i;
    }
    EXPECT_GT(usable, kCount / 2);
  }
}

TEST(FastMoments, BatchEigenvectorsEqualTheScalarOnes) {
  // Plane-like, general, a double smallest eigenvalue, collinear, isotropic and empty scatters:
  // every lane of every kernel gives SmallestEigenvector's unit vector and refined l1.
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> uni(-1, 1);
  constexpr int kCount = 600;
  std::vector<double> columns[6], l1(kCount), l2(kCount), l3(kCount);
  std::vector<SymEigen3> expected(kCount);
  for (int i = 0; i < kCount; ++i) {
    const Eigen::Matrix3d a = Eigen::Matrix3d::NullaryExpr([&] { return uni(rng); });
    Eigen::Matrix3d c = a * a.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
    Eigen::Vector3d ev = es.eigenvalues();
    if (i % 6 == 0) ev(0) = ev(2) * 1e-9;   // plane-like
    if (i % 6 == 1) ev(1) = ev(0);          // a double smallest eigenvalue
    if (i % 6 == 2) ev(0) = ev(1) = 0.0;    // collinear points
    if (i % 6 == 3) ev.setConstant(ev(2));  // isotropic
    if (i % 60 == 4) ev.setZero();          // no points
    c = es.eigenvectors() * ev.asDiagonal() * es.eigenvectors().transpose();
    const double u[6] = {c(0, 0), c(0, 1), c(0, 2), c(1, 1), c(1, 2), c(2, 2)};
    for (int j = 0; j < 6; ++j) columns[j].push_back(u[j]);
    SymEigenvaluesAscending(u, l1[i], l2[i], l3[i]);
    expected[i].l1 = l1[i];
    expected[i].l2 = l2[i];
    expected[i].l3 = l3[i];
    SmallestEigenvector(u, expected[i]);
  }
  const double* c[6];
  for (int j = 0; j < 6; ++j) c[j] = columns[j].data();
  const std::vector<SimdKernel> kernels = KernelsOfThisCpu();
  for (SimdKernel kernel : kernels) {
    SCOPED_TRACE(::testing::Message() << "kernel " << static_cast<int>(kernel));
    std::vector<double> vx(kCount), vy(kCount), vz(kCount), refined(kCount);
    double* const v[3] = {vx.data(), vy.data(), vz.data()};
    SmallestEigenvectorBatch(c, l1.data(), l2.data(), l3.data(), kCount, v, refined.data(), kernel);
    for (int i = 0; i < kCount; ++i) {
      EXPECT_DOUBLE_EQ(vx[i], expected[i].v1.x()) << i;
      EXPECT_DOUBLE_EQ(vy[i], expected[i].v1.y()) << i;
      EXPECT_DOUBLE_EQ(vz[i], expected[i].v1.z()) << i;
      EXPECT_DOUBLE_EQ(refined[i], expected[i].l1) << i;
      if (i % 60 != 4) {
        EXPECT_NEAR(Eigen::Vector3d(vx[i], vy[i], vz[i]).norm(), 1.0, 1e-12) << i;
      }
    }
  }
}

TEST(FastMoments, GridNoiseBatchEqualsTheMomentSumsFigures) {
  // Grids of noisy points at 0.5-8 m (spread from flat to round, normals from the fit or random):
  // every lane of every kernel gives exactly MomentSums's IsotropicMse, NormalTilt and
  // EffectiveMse, and the angle tolerance from them, as GBRG's classification used to form them.
  std::mt19937 rng(37);
  std::uniform_real_distribution<double> uni(-1, 1), depth(0.5, 8.0);
  constexpr int kCount = 500;
  constexpr double kEta = 0.2, kEtaSigmas = 2.0;
  std::vector<double> k, w[6], l2, v[3];
  std::vector<MomentSums> grids;
  for (int i = 0; i < kCount; ++i) {
    MomentSums m;
    const double z = depth(rng), flat = i % 5 == 0 ? 1.0 : 0.01 * (i % 4);
    for (int p = 0; p < 3 + i % 7; ++p) {
      m.AddPosition(0.005 * z * uni(rng), 0.005 * z * uni(rng), z + flat * 0.005 * z * uni(rng));
    }
    m.SetUniformNoise(1e-6 * z * z);
    double c[6];
    m.Scatter(c);
    const SymEigen3 e = SymEigen3Smallest(c);
    const Eigen::Vector3d n =
        i % 3 == 0 ? Eigen::Vector3d(uni(rng), uni(rng), uni(rng)).normalized() : e.v1;
    grids.push_back(m);
    k.push_back(m.k);
    const double wm[6] = {m.wxx, m.wxy, m.wxz, m.wyy, m.wyz, m.wzz};
    for (int j = 0; j < 6; ++j) w[j].push_back(wm[j]);
    l2.push_back(i % 50 == 7 ? 0.0 : e.l2);  // a degenerate spread too
    for (int j = 0; j < 3; ++j) v[j].push_back(n(j));
  }
  const double* wc[6];
  for (int j = 0; j < 6; ++j) wc[j] = w[j].data();
  const double* vc[3] = {v[0].data(), v[1].data(), v[2].data()};
  for (SimdKernel kernel : KernelsOfThisCpu()) {
    SCOPED_TRACE(::testing::Message() << "kernel " << static_cast<int>(kernel));
    std::vector<double> iso(kCount), tilt(kCount), effective(kCount), angle(kCount);
    GridNoiseBatch(k.data(), wc, l2.data(), vc, kCount, kEta, kEtaSigmas, iso.data(), tilt.data(),
                   effective.data(), angle.data(), kernel);
    for (int i = 0; i < kCount; ++i) {
      const MomentSums& m = grids[i];
      const Eigen::Vector3d n(v[0][i], v[1][i], v[2][i]);
      const double expected_tilt = m.NormalTilt(l2[i]);
      const double expected_effective = m.EffectiveMse(n, expected_tilt);
      EXPECT_EQ(iso[i], m.IsotropicMse()) << i;
      EXPECT_EQ(tilt[i], expected_tilt) << i;
      EXPECT_EQ(effective[i], expected_effective) << i;
      EXPECT_EQ(angle[i],
                kEta + kEtaSigmas * std::sqrt(expected_effective / std::max(l2[i], 1e-18)))
          << i;
    }
  }
}

TEST(FastMoments, IncrementalFitEqualsBatchFit) {
  const auto pts = NoisyPlanePoints(400, 6, 0.005, Eigen::Vector3d(0.1, 0.9, 0.3), 1.2);
  MomentSums inc;
  FastFit prev;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    inc.Add(pts[i].x(), pts[i].y(), pts[i].z(), 0.0);
    if (i < 3) continue;
    if (i == 3) prev = FitSums(inc);
    // Batch fit of the first i+1 points with Eigen's general solver.
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (std::size_t j = 0; j <= i; ++j) mean += pts[j];
    mean /= static_cast<double>(i + 1);
    Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
    for (std::size_t j = 0; j <= i; ++j) c += (pts[j] - mean) * (pts[j] - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
    Eigen::Vector3d n = es.eigenvectors().col(0);
    if (n.dot(mean) < 0) n = -n;
    const FastFit f = FitSums(inc);
    EXPECT_NEAR(f.normal.dot(n), 1.0, 1e-9) << i;
    EXPECT_NEAR(f.d, n.dot(mean), 1e-9) << i;
    EXPECT_NEAR(f.mse, es.eigenvalues()(0) / (i + 1), 1e-12) << i;
    // The growers' per-join update from the previous normal gives the same plane.
    const FastFit r = RefitFrom(inc, prev.normal);
    EXPECT_NEAR(r.normal.dot(n), 1.0, 1e-9) << i;
    EXPECT_NEAR(r.d, n.dot(mean), 1e-9) << i;
    EXPECT_NEAR(r.mse, es.eigenvalues()(0) / (i + 1), 1e-12) << i;
    EXPECT_NEAR(r.l2, es.eigenvalues()(1), 1e-9 * es.eigenvalues()(2)) << i;
    EXPECT_NEAR(r.l3, es.eigenvalues()(2), 1e-9 * es.eigenvalues()(2)) << i;
    prev = r;
  }
}

TEST(FastMoments, RefitFromPoorlySeparatedSpreadsEqualsBatchFit) {
  // A young region's points: noise across the plane from 6 to 27 cm against a 0.4 m narrow side,
  // so l1 / l2 from 0.02 to 0.45 (beyond the plain power iteration's reach), refitted from
  // normals up to 30 deg off, and from one in the plane (the answer's second eigenvector).
  for (const double noise : {0.06, 0.1, 0.15, 0.2, 0.27}) {
    const auto pts = NoisyPlanePoints(300, 9, noise, Eigen::Vector3d(0.3, -0.2, 1.0), 2.5);
    MomentSums sums;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : pts) {
      sums.Add(p.x(), p.y(), p.z(), 0.0);
      mean += p;
    }
    mean /= static_cast<double>(pts.size());
    Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
    for (const auto& p : pts) c += (p - mean) * (p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
    Eigen::Vector3d n = es.eigenvectors().col(0);
    if (n.dot(mean) < 0) n = -n;
    const double ratio = es.eigenvalues()(0) / es.eigenvalues()(1);
    ASSERT_GT(ratio, 0.015) << noise;
    ASSERT_LT(ratio, 0.5) << noise;
    std::vector<Eigen::Vector3d> starts = {es.eigenvectors().col(1)};
    const Eigen::Vector3d axis = n.unitOrthogonal();
    for (const double deg : {0.0, 1.0, 5.0, 15.0, 30.0}) {
      starts.push_back(Eigen::AngleAxisd(deg * M_PI / 180.0, axis) * n);
    }
    for (std::size_t i = 0; i < starts.size(); ++i) {
      SCOPED_TRACE(::testing::Message()
                   << "noise " << noise << " l1/l2 " << ratio << " start " << i);
      const FastFit r = RefitFrom(sums, starts[i]);
      EXPECT_NEAR(r.normal.dot(n), 1.0, 1e-12);
      EXPECT_NEAR(r.d, n.dot(mean), 1e-9);
      EXPECT_NEAR(r.l1, es.eigenvalues()(0), 1e-9 * es.eigenvalues()(2));
      EXPECT_NEAR(r.l2, es.eigenvalues()(1), 1e-9 * es.eigenvalues()(2));
      EXPECT_NEAR(r.l3, es.eigenvalues()(2), 1e-9 * es.eigenvalues()(2));
    }
  }
}

TEST(FastMoments, PixelBlockSumsEqualPointByPointSums) {
  // A 7 x 5 block inside an 11 x 6 organized cloud: points 0.5-5 m away, some without depth (NaN),
  // some behind a scanner's origin (z < 0, range > 0).
  const int width = 11, height = 6, x0 = 2, y0 = 1, x1 = 9, y1 = 6;
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> lateral(-2.0f, 2.0f), depth(0.5f, 5.0f);
  std::vector<Eigen::Vector3f> cloud(width * height);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    cloud[i] = Eigen::Vector3f(lateral(rng), lateral(rng), depth(rng));
    if (i % 7 == 3) cloud[i].z() = std::numeric_limits<float>::quiet_NaN();
    if (i % 11 == 5) cloud[i].z() = -cloud[i].z();
  }
  DetectionParams kinect, laser;
  kinect.sigma0 = 0.0;  // uniform ray weight
  laser.sigma0 = 0.01;  // ray weight varies with the range
  for (const DetectionParams* params : {&kinect, &laser}) {
    for (bool spherical : {false, true}) {
      MomentSums expected;
      RaySums expected_rays;
      for (int y = y0; y < y1; ++y) {
        for (int x = x0; x < x1; ++x) {
          const Eigen::Vector3f& p = cloud[y * width + x];
          if (!std::isfinite(p.z())) continue;
          expected.AddPosition(p.x(), p.y(), p.z());
          const float s = spherical ? p.norm() : p.z();
          if (s > 0.0f) expected_rays.Add(p, s, params->RayFitWeight(s));
        }
      }
      ASSERT_GT(expected.k, 20);
      SCOPED_TRACE(::testing::Message()
                   << "spherical " << spherical << " sigma0 " << params->sigma0);
      MomentSums m;
      RaySums rays;
      SumPixelBlock(cloud.data(), width, x0, y0, x1, y1, spherical, *params, m, &rays);
      const double got[] = {m.k, m.sx, m.sy, m.sz, m.xx, m.xy, m.xz, m.yy, m.yz, m.zz};
      const double want[] = {expected.k,  expected.sx, expected.sy, expected.sz, expected.xx,
                             expected.xy, expected.xz, expected.yy, expected.yz, expected.zz};
      for (int i = 0; i < 10; ++i) EXPECT_NEAR(got[i], want[i], 1e-12 * (1 + std::abs(want[i])));
      const double got_rays[] = {rays.a00, rays.a01, rays.a02, rays.a11, rays.a12,
                                 rays.a22, rays.b0,  rays.b1,  rays.b2};
      const double want_rays[] = {expected_rays.a00, expected_rays.a01, expected_rays.a02,
                                  expected_rays.a11, expected_rays.a12, expected_rays.a22,
                                  expected_rays.b0,  expected_rays.b1,  expected_rays.b2};
      for (int i = 0; i < 9; ++i) {
        EXPECT_NEAR(got_rays[i], want_rays[i], 1e-12 * (1 + std::abs(want_rays[i])));
      }
      EXPECT_EQ(m.wxx, 0.0);  // W is the caller's
      // Without ray sums, the same moments.
      MomentSums only;
      SumPixelBlock(cloud.data(), width, x0, y0, x1, y1, spherical, *params, only, nullptr);
      EXPECT_EQ(only.k, m.k);
      EXPECT_NEAR(only.zz, m.zz, 1e-12 * m.zz);
    }
  }
}

TEST(FastMoments, GridRowSumsEqualBlockSumsOnEveryKernel) {
  // Every row of grids of a 37 x 11 cloud (no grid size divides 37), the last row of grids
  // included (where a wide load could read past the cloud), with invalid pixels and points
  // behind a scanner, for both ray weightings and both sensor models.
  const int width = 37, height = 11;
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> lateral(-2.0f, 2.0f), depth(0.5f, 5.0f);
  std::vector<Eigen::Vector3f> cloud(width * height);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    cloud[i] = Eigen::Vector3f(lateral(rng), lateral(rng), depth(rng));
    if (i % 5 == 1) cloud[i].z() = std::numeric_limits<float>::quiet_NaN();
    if (i % 13 == 4) cloud[i].z() = std::numeric_limits<float>::infinity();
    if (i % 11 == 5) cloud[i].z() = -cloud[i].z();
  }
  const std::vector<SimdKernel> kernels = KernelsOfThisCpu();
  DetectionParams kinect, laser;
  kinect.sigma0 = 0.0;
  laser.sigma0 = 0.01;
  for (const DetectionParams* params : {&kinect, &laser}) {
    for (bool spherical : {false, true}) {
      for (int k : {2, 3, 5, 7}) {
        const int cells = (width + k - 1) / k;
        for (int y0 = 0; y0 < height; y0 += k) {
          const int y1 = std::min(height, y0 + k);
          for (SimdKernel kernel : kernels) {
            SCOPED_TRACE(::testing::Message()
                         << "kernel " << static_cast<int>(kernel) << " k " << k << " y0 " << y0
                         << " spherical " << spherical << " sigma0 " << params->sigma0);
            std::vector<MomentSums> sums(cells);
            std::vector<RaySums> rays(cells);
            SumGridRow(cloud.data(), width, height, y0, y1, k, spherical, *params, sums.data(),
                       rays.data(), kernel);
            for (int cx = 0; cx < cells; ++cx) {
              MomentSums want;
              RaySums want_rays;
              SumPixelBlock(cloud.data(), width, cx * k, y0, std::min(width, cx * k + k), y1,
                            spherical, *params, want, &want_rays);
              const MomentSums& m = sums[cx];
              const RaySums& r = rays[cx];
              const double got[] = {m.k,   m.sx,  m.sy, m.sz,  m.xx,  m.xy,  m.xz,
                                    m.yy,  m.yz,  m.zz, r.a00, r.a01, r.a02, r.a11,
                                    r.a12, r.a22, r.b0, r.b1,  r.b2};
              const double expected[] = {want.k,        want.sx,       want.sy,       want.sz,
                                         want.xx,       want.xy,       want.xz,       want.yy,
                                         want.yz,       want.zz,       want_rays.a00, want_rays.a01,
                                         want_rays.a02, want_rays.a11, want_rays.a12, want_rays.a22,
                                         want_rays.b0,  want_rays.b1,  want_rays.b2};
              for (int i = 0; i < 19; ++i) {
                EXPECT_NEAR(got[i], expected[i], 1e-12 * (1 + std::abs(expected[i])))
                    << "grid " << cx << " sum " << i;
              }
            }
          }
        }
      }
    }
  }
}

TEST(FastMoments, FirstQuadrantSinCosMatchesTheLibrary) {
  double worst = 0.0;
  for (int i = 0; i <= 100000; ++i) {
    const double x = 0.5 * M_PI * i / 100000;
    double s, c;
    SinCosFirstQuadrant(x, s, c);
    worst = std::max({worst, std::abs(s - std::sin(x)), std::abs(c - std::cos(x))});
  }
  EXPECT_LT(worst, 1e-13);
}

TEST(FastMoments, DivisionFreeEpsilonTestEqualsThePlainOne) {
  // Noisy planes of many sizes and noise levels, tested about normals tilted from the fitted one
  // by up to 0.2 degrees, under both threshold models and with the count term on and off: the
  // growers' division-free test agrees with MseAbout < Epsilon(ExpectedMse) wherever the two
  // sides differ by more than rounding.
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  int decided = 0, accepted = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const double noise = 0.0005 * (1 + trial % 20);
    const auto pts = NoisyPlanePoints(3 + trial * 7 % 500, 100 + trial, noise,
                                      Eigen::Vector3d(uni(rng), uni(rng), 2.0), 1.0 + trial % 4);
    MomentSums m;
    for (const auto& p : pts) m.Add(p.x(), p.y(), p.z(), 1e-6 * (1 + trial % 5));
    const Eigen::Vector3d tilt(uni(rng), uni(rng), uni(rng));
    const Eigen::Vector3d n = (FitSums(m).normal + 0.001 * (trial % 4) * tilt).normalized();
    DetectionParams params;
    params.model = trial % 3 == 0 ? ThresholdModel::kConstant : ThresholdModel::kDepth;
    params.epsilon = 2e-6 * (1 + trial % 7);
    params.epsilon_sigmas = 0.5 * (trial % 4);
    params.epsilon_count_sigmas = trial % 2 == 0 ? 0.0 : 1.0;
    const double lhs = m.MseAbout(n), rhs = params.Epsilon(m.ExpectedMse(n), m.k);
    if (std::abs(lhs - rhs) <= 1e-9 * rhs) continue;  // at the boundary either answer is right
    ++decided;
    accepted += lhs < rhs;
    EXPECT_EQ(MseAboutWithinEpsilon(m, n, params), lhs < rhs) << trial;
  }
  // Both outcomes were exercised.
  EXPECT_GT(decided, 390);
  EXPECT_GT(accepted, 50);
  EXPECT_LT(accepted, decided - 50);
}

TEST(FastMoments, MapLabelsEqualsTheTableLookupOnEveryKernel) {
  // A table indexed from -1 and label images of every length around the eight-pixel step, mapped
  // to another image and in place.
  const std::vector<std::int32_t> shifted_table = {-1, 5, 3, -1, 9, 1};
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> label(-1, 4);
  for (const SimdKernel kernel : KernelsOfThisCpu()) {
    for (std::size_t n : {0, 1, 7, 8, 9, 16, 31, 1000}) {
      std::vector<std::int32_t> in(n), out(n, 42), expected(n);
      for (std::size_t i = 0; i < n; ++i) {
        in[i] = label(rng);
        expected[i] = shifted_table[static_cast<std::size_t>(in[i] + 1)];
      }
      MapLabels(shifted_table.data(), in.data(), out.data(), n, kernel);
      EXPECT_EQ(out, expected) << n;
      MapLabels(shifted_table.data(), in.data(), in.data(), n, kernel);
      EXPECT_EQ(in, expected) << n;
    }
  }
}

TEST(PlaneCovariance, RankThreePsdNullAlongNormalAndScalesWithNoise) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, 0.1, 1).normalized();
  const auto pts = NoisyPlanePoints(2000, 7, 0.0, n, 3.0);
  PlaneMoments m;
  for (const auto& p : pts) m.Add(p);
  const PlaneFit fit = m.Fit();
  const Eigen::Matrix4d cov = PlaneCovariance(m, fit.normal, 1e-4);
  EXPECT_LT((cov - cov.transpose()).norm(), 1e-15);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(cov);
  EXPECT_GT(es.eigenvalues()(0), -1e-15);
  EXPECT_LT(es.eigenvalues()(0), 1e-12 * es.eigenvalues()(3));  // rank 3
  EXPECT_GT(es.eigenvalues()(1), 0.0);
  Eigen::Vector4d null;
  null << fit.normal, 0.0;
  EXPECT_LT((cov * null).norm(), 1e-12 * cov.norm());
  const Eigen::Matrix4d cov2 = PlaneCovariance(m, fit.normal, 4e-4);
  EXPECT_LT((cov2 - 4.0 * cov).norm(), 1e-12 * cov2.norm());
}

TEST(PlaneCovariance, MatchesMonteCarloSpreadOfFits) {
  // Oracle: fit many noisy draws of the same patch; the sample covariance of (n, d) must agree
  // with the predicted one (sigma^2 known).
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.1, 1).normalized();
  const double sigma = 0.01, d = 2.0;
  const auto clean = NoisyPlanePoints(200, 8, 0.0, n, d);
  std::mt19937 rng(9);
  std::normal_distribution<double> gauss(0.0, sigma);
  std::vector<Eigen::Vector4d> samples;
  PlaneMoments clean_m;
  for (const auto& p : clean) clean_m.Add(p);
  for (int t = 0; t < 3000; ++t) {
    PlaneMoments m;
    for (const auto& p : clean) m.Add(Eigen::Vector3d(p + n * gauss(rng)));
    const PlaneFit f = m.Fit();
    Eigen::Vector4d s;
    s << f.normal, f.d;
    samples.push_back(s);
  }
  Eigen::Vector4d mean = Eigen::Vector4d::Zero();
  for (const auto& s : samples) mean += s;
  mean /= samples.size();
  Eigen::Matrix4d emp = Eigen::Matrix4d::Zero();
  for (const auto& s : samples) emp += (s - mean) * (s - mean).transpose();
  emp /= samples.size() - 1;
  const Eigen::Matrix4d pred = PlaneCovariance(clean_m, clean_m.Fit().normal, sigma * sigma);
  EXPECT_LT((emp - pred).norm(), 0.1 * pred.norm());
  EXPECT_NEAR(emp(3, 3), pred(3, 3), 0.15 * pred(3, 3));
}

}  // namespace
}  // namespace planeslam::detection

#pragma once
/// Flat, allocation-free moment sums and a closed-form 3x3 symmetric eigen solver: the inner loop
/// of both region growers (one fit per tested grid or point, paper eq. 5-6). Also the ray-fit
/// sums, and the batch kernels of GBRG's per-grid passes (AVX2 where the CPU has it, chosen at
/// run time).
///
/// Sums are kept about the origin in double (K, S = sum p, Q = sum p p^T, 10 doubles). Inputs are
/// float metres; with |p| < 100 m and K < 10^7 the cancellation in C = Q - S m^T (eq. 6) costs at
/// most ~1e-16 * K * |p|^2 absolutely, i.e. an MSE error below 1e-12 m^2, far under any threshold
/// here, so the reference-point shift that PlaneMoments does is not needed in the hot loop.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/plane_moments.hpp"

namespace planeslam::detection {

/// Sufficient statistics of a point set plus its noise moment W (used by the depth-dependent
/// thresholds and the covariance). Plain aggregate: Add/Merge are a few adds.
///
/// Noise model: a range sensor errs along the ray. A point p = (z/|r|) r measured with depth (or
/// range) noise sigma has covariance sigma^2 p p^T / z^2, so its variance along any unit normal n
/// is (sigma/z)^2 (n.p)^2. Summing w_i p_i p_i^T with w_i = (sigma_i / z_i)^2 gives
/// W = sum w_i p_i p_i^T, and the expected squared residual of the set about a plane with normal n
/// is n^T W n / K, for any n, in O(1). This is what makes grazing surfaces (noise mostly along the
/// surface) and facing surfaces (noise across it) comparable under one threshold.
struct MomentSums {
  double k = 0.0;                 ///< point count K
  double sx = 0, sy = 0, sz = 0;  ///< S = sum p [m]
  double xx = 0, xy = 0, xz = 0;  ///< Q = sum p p^T [m^2] (upper triangle)
  double yy = 0, yz = 0, zz = 0;
  double wxx = 0, wxy = 0, wxz = 0;  ///< W = sum w_i p_i p_i^T [m^2] (noise moment)
  double wyy = 0, wyz = 0, wzz = 0;

  /// Adds point (x, y, z) to K, S and Q only (W is then set by the caller, e.g. per grid).
  void AddPosition(double x, double y, double z) {
    k += 1.0;
    sx += x;
    sy += y;
    sz += z;
    xx += x * x;
    xy += x * y;
    xz += x * z;
    yy += y * y;
    yz += y * z;
    zz += z * z;
  }
  /// Adds point (x, y, z) whose relative ray noise is w = (sigma / depth)^2 [1].
  void Add(double x, double y, double z, double w) {
    AddPosition(x, y, z);
    wxx += w * (x * x);
    wxy += w * (x * y);
    wxz += w * (x * z);
    wyy += w * (y * y);
    wyz += w * (y * z);
    wzz += w * (z * z);
  }
  /// Sets this to `a` with point (x, y, z) of relative noise w added: the same sums as a copy of
  /// `a` and Add, without the copy.
  void SetSum(const MomentSums& a, double x, double y, double z, double w) {
    k = a.k + 1.0;
    sx = a.sx + x;
    sy = a.sy + y;
    sz = a.sz + z;
    xx = a.xx + x * x;
    xy = a.xy + x * y;
    xz = a.xz + x * z;
    yy = a.yy + y * y;
    yz = a.yz + y * z;
    zz = a.zz + z * z;
    wxx = a.wxx + w * (x * x);
    wxy = a.wxy + w * (x * y);
    wxz = a.wxz + w * (x * z);
    wyy = a.wyy + w * (y * y);
    wyz = a.wyz + w * (y * z);
    wzz = a.wzz + w * (z * z);
  }
  /// Sets W = w Q: the noise moment when every point has the same relative noise w.
  void SetUniformNoise(double w) {
    wxx = w * xx;
    wxy = w * xy;
    wxz = w * xz;
    wyy = w * yy;
    wyz = w * yz;
    wzz = w * zz;
  }
  void Merge(const MomentSums& o) {
    k += o.k;
    sx += o.sx;
    sy += o.sy;
    sz += o.sz;
    xx += o.xx;
    xy += o.xy;
    xz += o.xz;
    yy += o.yy;
    yz += o.yz;
    zz += o.zz;
    wxx += o.wxx;
    wxy += o.wxy;
    wxz += o.wxz;
    wyy += o.wyy;
    wyz += o.wyz;
    wzz += o.wzz;
  }
  /// Removes a subset previously added (exact up to round-off).
  void Subtract(const MomentSums& o) {
    k -= o.k;
    sx -= o.sx;
    sy -= o.sy;
    sz -= o.sz;
    xx -= o.xx;
    xy -= o.xy;
    xz -= o.xz;
    yy -= o.yy;
    yz -= o.yz;
    zz -= o.zz;
    wxx -= o.wxx;
    wxy -= o.wxy;
    wxz -= o.wxz;
    wyy -= o.wyy;
    wyz -= o.wyz;
    wzz -= o.wzz;
  }
  Eigen::Vector3d Centroid() const { return Eigen::Vector3d(sx, sy, sz) / k; }
  /// n^T W n: summed noise variance of the points along unit normal n [m^2].
  double NoiseAlong(const Eigen::Vector3d& n) const {
    return wxx * n.x() * n.x() + wyy * n.y() * n.y() + wzz * n.z() * n.z() +
           2.0 * (wxy * n.x() * n.y() + wxz * n.x() * n.z() + wyz * n.y() * n.z());
  }
  /// Expected MSE of the points about a plane with unit normal n under the noise model [m^2].
  double ExpectedMse(const Eigen::Vector3d& n) const { return k > 0 ? NoiseAlong(n) / k : 0.0; }
  /// Mean noise variance in any direction, trace(W)/K (the full ray noise) [m^2].
  double IsotropicMse() const { return k > 0 ? (wxx + wyy + wzz) / k : 0.0; }
  /// Expected MSE along a normal n that is itself uncertain by about `tilt` [rad]: the noise
  /// along n plus the ray noise leaking in through the tilt, sigma_eff = sigma_n + sigma tilt,
  /// capped at the full ray noise. A 3x3 grid at 4 m has a random normal (tilt ~ 1), so its tests
  /// see the full noise; a large region's normal is sharp and its tests see only sigma_n.
  double EffectiveMse(const Eigen::Vector3d& n, double tilt) const {
    const double iso = IsotropicMse();
    const double s = std::sqrt(std::max(ExpectedMse(n), 0.0)) +
                     std::sqrt(iso) * std::min(1.0, std::max(tilt, 0.0));
    return std::min(s * s, iso);
  }
  /// Two-sigma tilt of the normal fitted to these points: 2 sqrt(sigma^2 / l2) [rad].
  double NormalTilt(double l2) const {
    return 2.0 * std::sqrt(IsotropicMse() / std::max(l2, 1e-30));
  }
  /// MSE of the points about the plane with unit normal n through their centroid,
  /// (n^T Q n - (n.S)^2 / K) / K: at least the fitted MSE lambda_min / K, equal to it when n is
  /// the fitted normal. The growers' cheap MSE test between refits.
  double MseAbout(const Eigen::Vector3d& n) const {
    double nqn, ns;
    AlongNormal(n, nqn, ns);
    return std::max(0.0, nqn - ns * ns / k) / k;
  }
  /// n^T Q n [m^2] and n.S [m]: the second and first moments along unit normal n (MseAbout).
  void AlongNormal(const Eigen::Vector3d& n, double& nqn, double& ns) const {
    nqn = xx * n.x() * n.x() + yy * n.y() * n.y() + zz * n.z() * n.z() +
          2.0 * (xy * n.x() * n.y() + xz * n.x() * n.z() + yz * n.y() * n.z());
    ns = sx * n.x() + sy * n.y() + sz * n.z();
  }
  /// C = Q - S m^T (eq. 6) as the upper triangle {c00, c01, c02, c11, c12, c22}. Inline: GBRG
  /// takes it of every grid.
  void Scatter(double c[6]) const {
    if (k <= 0) {
      for (int i = 0; i < 6; ++i) c[i] = 0.0;
      return;
    }
    const double inv = 1.0 / k;
    const double mx = sx * inv, my = sy * inv, mz = sz * inv;
    // Eq. (6): C = Q - S m^T.
    c[0] = xx - sx * mx;
    c[1] = xy - sx * my;
    c[2] = xz - sx * mz;
    c[3] = yy - sy * my;
    c[4] = yz - sy * mz;
    c[5] = zz - sz * mz;
  }
  /// The same statistics as a PlaneMoments (reference point = origin).
  PlaneMoments ToPlaneMoments() const;
};

/// Whether m.MseAbout(n) < params.Epsilon(m.ExpectedMse(n), m.k), given K = k, n^T Q n = nqn,
/// n.S = ns and n^T W n = nwn of the sums m: the growers' test of a join between refits, once per
/// tested grid or point. The same inequality without a division or a
/// square root, whose latencies chain through every test: with M the MSE about n, E the expected
/// MSE, eps the base epsilon and s its sigmas, M < (sqrt(eps) + s sqrt(E))^2 holds iff
/// D = M - eps - s^2 E < 2 s sqrt(eps E), i.e. D < 0 or D^2 < 4 s^2 eps E; both sides are
/// multiplied by K^2 (resp. K^4) to drop the divisions. Equal to the plain test but for rounding
/// (~1e-16 relative) at the boundary.
inline bool MseAboutWithinEpsilon(double k, double nqn, double ns, double nwn,
                                  const DetectionParams& params) {
  if (!(k > 0)) return false;  // no points: the plain test's MSE is undefined (NaN), it rejects
  const double k2_mse = std::max(0.0, k * nqn - ns * ns);  // K^2 MseAbout(n)
  const double k2 = k * k;
  if (params.model != ThresholdModel::kDepth) return k2_mse < params.epsilon * k2;
  const double sigmas = params.EpsilonSigmas(k);
  const double k2_expected = std::max(0.0, k * nwn);  // K^2 ExpectedMse(n)
  const double s2 = sigmas * sigmas;
  const double k2_d = k2_mse - params.epsilon * k2 - s2 * k2_expected;
  return k2_d < 0.0 || k2_d * k2_d < 4.0 * s2 * params.epsilon * k2_expected * k2;
}
/// The same test from the moment sums: n^T Q n, n.S and n^T W n formed from them.
inline bool MseAboutWithinEpsilon(const MomentSums& m, const Eigen::Vector3d& n,
                                  const DetectionParams& params) {
  if (!(m.k > 0)) return false;
  double nqn, ns;
  m.AlongNormal(n, nqn, ns);
  const double nwn = params.model == ThresholdModel::kDepth ? m.NoiseAlong(n) : 0.0;
  return MseAboutWithinEpsilon(m.k, nqn, ns, nwn, params);
}

/// Normal equations of the ray fit of one region: 1/s_i = m.q_i with q_i = p_i / s_i the ray
/// of pixel i scaled to unit depth (unit range for a scanner) and m = n / d; A = sum w q q^T
/// (upper triangle), b = sum w q / s.
struct RaySums {
  double a00 = 0, a01 = 0, a02 = 0, a11 = 0, a12 = 0, a22 = 0;
  double b0 = 0, b1 = 0, b2 = 0;

  /// Adds pixel p at depth s with weight w (a negative w removes it). The ray is formed in
  /// float (one division; 1e-7 relative, far below the depth noise) and summed in double.
  void Add(const Eigen::Vector3f& p, float s, double w) {
    const float inv_f = 1.0f / s;
    const double inv = inv_f;
    const double qx = p.x() * inv_f, qy = p.y() * inv_f, qz = p.z() * inv_f;
    const double wx = w * qx, wy = w * qy, wz = w * qz;
    a00 += wx * qx;
    a01 += wx * qy;
    a02 += wx * qz;
    a11 += wy * qy;
    a12 += wy * qz;
    a22 += wz * qz;
    b0 += wx * inv;
    b1 += wy * inv;
    b2 += wz * inv;
  }
  void Add(const RaySums& o) {
    a00 += o.a00;
    a01 += o.a01;
    a02 += o.a02;
    a11 += o.a11;
    a12 += o.a12;
    a22 += o.a22;
    b0 += o.b0;
    b1 += o.b1;
    b2 += o.b2;
  }
  /// Removes sums added before (exact up to round-off).
  void Subtract(const RaySums& o) {
    a00 -= o.a00;
    a01 -= o.a01;
    a02 -= o.a02;
    a11 -= o.a11;
    a12 -= o.a12;
    a22 -= o.a22;
    b0 -= o.b0;
    b1 -= o.b1;
    b2 -= o.b2;
  }
};

/// The instruction set of a batch kernel (SumGridRow, SymEigenvaluesNewtonBatch,
/// SmallestEigenvectorBatch).
enum class SimdKernel {
  kScalar,  ///< the compiler's baseline (SSE2 on x86-64): any CPU
  kAvx2,    ///< AVX2 + FMA: four doubles at a time; only where FastestSimdKernel() says so
};
/// The fastest kernel this CPU runs, checked once at run time (the binary stays portable).
SimdKernel FastestSimdKernel();

/// Adds to `m` K, S and Q (not W) of the pixels of the block [x0, x1) x [y0, y1) of an organized
/// cloud (row-major, `width` points a row) whose z is finite, and, when `rays` is not null, to
/// `rays` those of them at depth s > 0 (z, or the range when `spherical`) with weight
/// params.RayFitWeight(s). The reference for SumGridRow, which uses it where its four-grid
/// kernel does not apply.
void SumPixelBlock(const Eigen::Vector3f* points, int width, int x0, int y0, int x1, int y1,
                   bool spherical, const DetectionParams& params, MomentSums& m, RaySums* rays);

/// SumPixelBlock of every k x k grid of one row of grids: grid cx covers columns
/// [cx k, min(width, cx k + k)) of rows [y0, y1) of an organized cloud of width x height points,
/// and its sums are written to sums[cx] (and rays[cx] when `rays` is not null), for cx in
/// [0, ceil(width / k)). W is left 0. The AVX2 kernel sums four neighbouring grids at once, one a
/// lane, in the same pixel order as SumPixelBlock; their results differ by the rounding of fused
/// multiply-adds only (~1e-16 relative). `next_sums` and `next_rays`, when not null, are where the
/// caller's next row of grids goes: fetched for writing while this row is summed.
void SumGridRow(const Eigen::Vector3f* points, int width, int height, int y0, int y1, int k,
                bool spherical, const DetectionParams& params, MomentSums* sums, RaySums* rays,
                SimdKernel kernel, const MomentSums* next_sums = nullptr,
                const RaySums* next_rays = nullptr);

/// out[i] = shifted_table[in[i] + 1] for i < n, every in[i] >= -1 (a label image through a table
/// indexed from -1: region -> merged region, region -> plane id). Eight pixels per gather with
/// AVX2, where the plain loop reads one label at a time. `out` may be `in`.
void MapLabels(const std::int32_t* shifted_table, const std::int32_t* in, std::int32_t* out,
               std::size_t n, SimdKernel kernel = FastestSimdKernel());

/// Eigen decomposition of a symmetric 3x3 matrix as needed by plane fitting.
struct SymEigen3 {
  double l1 = 0, l2 = 0, l3 = 0;                  ///< eigenvalues, ascending
  Eigen::Vector3d v1 = Eigen::Vector3d::UnitZ();  ///< unit eigenvector of l1
};

/// Eigenvalues only (trigonometric closed form, Smith 1961), ascending. `c` = upper triangle.
void SymEigenvalues3(const double c[6], double& l1, double& l2, double& l3);
/// Eigenvalues and the eigenvector of the smallest one. The eigenvalues come from Newton's method
/// on the characteristic polynomial when l1 is well separated (planar sets: no trigonometry),
/// else from SymEigenvalues3; the eigenvector is the cross product of two rows of C - l1 I
/// (the best-conditioned pair), and l1 is refined as the Rayleigh quotient v1^T C v1, which is
/// accurate to round-off even when l1 << l3.
SymEigen3 SymEigen3Smallest(const double c[6]);
/// The two halves of SymEigen3Smallest, for callers that need the eigenvector only sometimes:
/// the eigenvalues, ascending (Newton or the closed form, as above; Newton stops at a step below
/// 1e-14 of the trace)...
void SymEigenvaluesAscending(const double c[6], double& l1, double& l2, double& l3);
/// ...and, given them in e, the eigenvector of the smallest (cross product of two rows of
/// C - l1 I) with l1 refined as its Rayleigh quotient.
void SmallestEigenvector(const double c[6], SymEigen3& e);
/// SmallestEigenvector for many matrices at once (structure of arrays as below, eigenvalues
/// l1 <= l2 <= l3 given): v[0..2][i] the unit eigenvector, l1_refined[i] its Rayleigh quotient.
/// The same arithmetic as SmallestEigenvector, lane by lane.
void SmallestEigenvectorBatch(const double* const c[6], const double* l1, const double* l2,
                              const double* l3, int n, double* const v[3], double* l1_refined,
                              SimdKernel kernel = FastestSimdKernel());
/// GBRG's noise figures of many grids at once (structure of arrays; grid i has K = k[i] > 0, the
/// noise moment's upper triangle {w[0][i], ..., w[5][i]} = {wxx, wxy, wxz, wyy, wyz, wzz}, second
/// eigenvalue l2[i] and unit normal (v[0][i], v[1][i], v[2][i])): isotropic[i] =
/// IsotropicMse(), tilt[i] = NormalTilt(l2), effective[i] = EffectiveMse(v, tilt[i]) and
/// angle[i] = eta + eta_sigmas sqrt(effective[i] / max(l2, 1e-18)), its normal's angle tolerance
/// [rad]. MomentSums's own arithmetic lane by lane (no fused multiply-adds), so the results are
/// equal; four lanes at once with AVX2. Each grid's dozen divisions and square roots, in a loop
/// that branches on them, held up the classification rules.
void GridNoiseBatch(const double* k, const double* const w[6], const double* l2,
                    const double* const v[3], int n, double eta, double eta_sigmas,
                    double* isotropic, double* tilt, double* effective, double* angle,
                    SimdKernel kernel = FastestSimdKernel());
/// The Newton half of SymEigenvaluesAscending for many matrices at once (GBRG's classification),
/// stopping at a step below relative_tolerance times the trace. Matrix i is {c[0][i], ...,
/// c[5][i]} (upper triangle, structure of arrays). A fixed number of steps and no branches let
/// the compiler vectorise the loop and overlap the divisions of different matrices, where one
/// matrix at a time waits on each division in turn. ok[i] = 0 (else 1) where Newton does not
/// apply or converge within its steps: use SymEigenvalues3 there.
void SymEigenvaluesNewtonBatch(const double* const c[6], int n, double relative_tolerance,
                               double* l1, double* l2, double* l3, double* ok,
                               SimdKernel kernel = FastestSimdKernel());

/// sin(x) and cos(x) for x in [0, pi / 2] to better than 1e-13, as two short polynomials: the
/// growers' angle tolerances need both for every planar grid, where libm's sincos costs several
/// times as much. About pi / 4: with y = x - pi / 4 in [-pi / 4, pi / 4], sin x = (sin y + cos y) /
/// sqrt 2 and cos x = (cos y - sin y) / sqrt 2, with Taylor series to y^13 and y^14.
inline void SinCosFirstQuadrant(double x, double& sin_x, double& cos_x) {
  const double y = x - 0.78539816339744830962, y2 = y * y;
  const double sin_y =
      y * (1.0 +
           y2 * (-1.0 / 6 +
                 y2 * (1.0 / 120 + y2 * (-1.0 / 5040 +
                                         y2 * (1.0 / 362880 + y2 * (-1.0 / 39916800 +
                                                                    y2 * (1.0 / 6227020800.0)))))));
  const double cos_y =
      1.0 +
      y2 * (-0.5 + y2 * (1.0 / 24 +
                         y2 * (-1.0 / 720 +
                               y2 * (1.0 / 40320 +
                                     y2 * (-1.0 / 3628800 + y2 * (1.0 / 479001600.0 +
                                                                  y2 * (-1.0 / 87178291200.0)))))));
  constexpr double kInvSqrt2 = 0.70710678118654752440;
  sin_x = (sin_y + cos_y) * kInvSqrt2;
  cos_x = (cos_y - sin_y) * kInvSqrt2;
}

/// Plane fitted to moment sums (eq. 3-6): unit normal oriented so that d = n.m >= 0.
struct FastFit {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double d = 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  double l1 = 0, l2 = 0, l3 = 0;  ///< scatter eigenvalues, ascending [m^2]
  double mse = 0.0;               ///< l1 / K [m^2] (eq. 3)
};
/// Fits a plane to `m` (K >= 3 expected; fewer gives mse = 0 and an arbitrary normal).
FastFit FitSums(const MomentSums& m);

/// The same fit, updated from a nearby normal `n0` (the region's plane before the last join):
/// two steps of power iteration on the adjugate of C (adj C = det(C) C^-1, so no division and no
/// trouble when C is singular, i.e. exactly planar points) converge to the smallest eigenvector
/// by a factor l1/l2 each; l1 is the Rayleigh quotient and l2, l3 follow from the trace and the
/// second invariant. When l1 > 0.01 l2 (poorly separated: young regions), two more steps on the
/// adjugate of C - l1 I (shifted by the Rayleigh quotient) converge by about the square of the
/// angle each; FitSums only when l1 > l2 / 2 remains or n0 is orthogonal to the answer. The
/// normal equals FitSums' to ~1e-4 (l1/l2)^2 relative on the first path, ~1e-8 rad on the second.
/// Costs about 60 flops (120 when shifted) and two square roots (four) instead of acos/cos/sin:
/// the per-join refit of both growers.
FastFit RefitFrom(const MomentSums& m, const Eigen::Vector3d& n0);

}  // namespace planeslam::detection

#include "fast_moments.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <type_traits>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define PLANESLAM_X86 1
#endif

#include "planeslam/detection/detection_config.hpp"
#include "region_common.hpp"

namespace planeslam::detection {

PlaneMoments MomentSums::ToPlaneMoments() const {
  Eigen::Matrix3d q;
  q << xx, xy, xz, xy, yy, yz, xz, yz, zz;
  return PlaneMoments::FromSums(static_cast<std::int64_t>(std::llround(k)),
                                Eigen::Vector3d(sx, sy, sz), q);
}

void SymEigenvalues3(const double c[6], double& l1, double& l2, double& l3) {
  const double m = (c[0] + c[3] + c[5]) / 3.0;
  const double b00 = c[0] - m, b11 = c[3] - m, b22 = c[5] - m;
  const double off = c[1] * c[1] + c[2] * c[2] + c[4] * c[4];
  const double p = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * off) / 6.0;
  if (p <= 1e-300) {
    l1 = l2 = l3 = m;
    return;
  }
  // det(B)/2 with B = C - m I; r = det(B/sqrt(p))/2 = cos(3 phi).
  const double det = b00 * (b11 * b22 - c[4] * c[4]) - c[1] * (c[1] * b22 - c[4] * c[2]) +
                     c[2] * (c[1] * c[4] - b11 * c[2]);
  const double sp = std::sqrt(p);
  double r = det / (2.0 * p * sp);
  r = std::clamp(r, -1.0, 1.0);
  const double phi = std::acos(r) / 3.0;
  const double cphi = std::cos(phi), sphi = std::sin(phi);
  // cos(phi + 2 pi / 3) = -cos(phi)/2 - sqrt(3)/2 sin(phi)
  l3 = m + 2.0 * sp * cphi;
  l1 = m + 2.0 * sp * (-0.5 * cphi - 0.8660254037844386 * sphi);
  l2 = 3.0 * m - l1 - l3;
  if (l2 < l1) std::swap(l1, l2);
  if (l3 < l2) std::swap(l2, l3);
}

namespace {

/// Newton steps before the closed form takes over. Planar sets converge in 3-5; grids of noise
/// (l1 near l2) need more, and each grid left to the closed form (acos, cos) costs far more than
/// a step. The batch loop is unrolled over the steps, so many more steps cost more than they
/// save.
constexpr int kNewtonSteps = 8;

/// The characteristic polynomial p(l) = l^3 - t l^2 + m l - det of a symmetric C (upper triangle
/// c00 c01 c02 c11 c12 c22).
struct CharacteristicPolynomial {
  double t, m, det;
};
inline CharacteristicPolynomial Characteristic(double c00, double c01, double c02, double c11,
                                               double c12, double c22) {
  const double m00 = c11 * c22 - c12 * c12, m11 = c00 * c22 - c02 * c02,
               m22 = c00 * c11 - c01 * c01;
  return {c00 + c11 + c22, m00 + m11 + m22,
          c00 * m00 + c01 * (c02 * c12 - c01 * c22) + c02 * (c01 * c12 - c02 * c11)};
}
/// One Newton step on p from l; `slope` = p'(l). The division is unconditional (a step taken at
/// a slope <= 0 is refused by the callers), which keeps the batch loop free of branches.
inline double NewtonStep(const CharacteristicPolynomial& q, double l, double& slope) {
  const double p = ((l - q.t) * l + q.m) * l - q.det;
  slope = (3.0 * l - 2.0 * q.t) * l + q.m;
  return -p / (slope > 0 ? slope : 1.0);
}
/// l2 and l3 given l1: they solve l2 + l3 = t - l1, l2 l3 = m - l1 (t - l1). l2 is l2 l3 / l3,
/// not (s - disc) / 2, which cancels when l2 << l3.
inline void UpperEigenvalues(const CharacteristicPolynomial& q, double l1, double& l2, double& l3) {
  const double s = q.t - l1;         // l2 + l3
  const double prod = q.m - l1 * s;  // l2 l3
  const double disc = std::sqrt(std::max(0.0, s * s - 4.0 * prod));
  l3 = 0.5 * (s + disc);
  const double quotient = prod / (l3 > 0 ? l3 : 1.0);  // unconditional, as above
  l2 = l3 > 0 ? quotient : 0.0;
}

/// Eigenvalues of a positive semi-definite C whose smallest one is well separated (the common case
/// in plane fitting), without trigonometry: Newton on the characteristic polynomial from l = 0.
/// p is increasing and concave on [0, l1] (p'' = 6 l - 2 t < 0 below t/3 >= l1), so the iterates
/// rise monotonically to l1 with no overshoot, quadratically once near it; then UpperEigenvalues.
/// Returns false (use the closed form) when C is not PSD or l1 is too close to l2 to converge in
/// a few steps.
bool SymEigenvaluesNewton(const double c[6], double relative_tolerance, double& l1, double& l2,
                          double& l3) {
  const CharacteristicPolynomial q = Characteristic(c[0], c[1], c[2], c[3], c[4], c[5]);
  if (!(q.t > 0) || !(q.m > 0) || q.det < 0) return false;
  double l = 0.0;
  bool converged = false;
  for (int it = 0; it < kNewtonSteps; ++it) {
    double slope;
    const double step = NewtonStep(q, l, slope);
    if (!(slope > 0)) return false;
    l += step;
    if (std::abs(step) <= relative_tolerance * q.t) {
      converged = true;
      break;
    }
  }
  if (!converged) return false;
  UpperEigenvalues(q, l, l2, l3);
  l1 = l;
  return l1 <= l2 && l2 <= l3;
}

/// One matrix of SymEigenvaluesNewtonBatch: SymEigenvaluesNewton with every lane taking all steps
/// (once converged a step is ~0, and the steps shrink monotonically, so "the last step is small"
/// is "some step was small"). Flags are doubles (1 or 0) selected like the values, not branches:
/// SSE2 vectorises that.
struct NewtonLane {
  CharacteristicPolynomial q;
  double l = 0.0, step = 0.0, good = 1.0;
};
__attribute__((always_inline)) inline NewtonLane StartNewtonLane(double c00, double c01, double c02,
                                                                 double c11, double c12,
                                                                 double c22) {
  NewtonLane a;
  a.q = Characteristic(c00, c01, c02, c11, c12, c22);
  a.good = (a.q.t > 0) ? 1.0 : 0.0;
  a.good = (a.q.m > 0) ? a.good : 0.0;
  a.good = (a.q.det >= 0) ? a.good : 0.0;
  return a;
}
__attribute__((always_inline)) inline void NewtonLaneStep(NewtonLane& a) {
  double slope;
  a.step = NewtonStep(a.q, a.l, slope);
  a.good = (slope > 0) ? a.good : 0.0;
  a.l += a.step;
}
__attribute__((always_inline)) inline void FinishNewtonLane(NewtonLane a, double relative_tolerance,
                                                            double& l1, double& l2, double& l3,
                                                            double& ok) {
  a.good = (std::abs(a.step) <= relative_tolerance * a.q.t) ? a.good : 0.0;
  double mid, hi;
  UpperEigenvalues(a.q, a.l, mid, hi);
  l1 = a.l;
  l2 = mid;
  l3 = hi;
  a.good = (a.l <= mid) ? a.good : 0.0;
  ok = (mid <= hi) ? a.good : 0.0;
}

/// The loop of SymEigenvaluesNewtonBatch. Restrict parameters (distinct arrays) let the compiler
/// vectorise it without run-time overlap checks. Inlined into one copy per instruction set.
/// Matrices i and i + n/2 step side by side: each step waits on a division, and two independent
/// chains keep the divider busy.
__attribute__((always_inline)) inline void NewtonBatchLoop(
    const double* __restrict c0, const double* __restrict c1, const double* __restrict c2,
    const double* __restrict c3, const double* __restrict c4, const double* __restrict c5, int n,
    double relative_tolerance, double* __restrict out1, double* __restrict out2,
    double* __restrict out3, double* __restrict out_ok) {
  const int half = n / 2;
  for (int i = 0; i < half; ++i) {
    const int j = i + half;
    NewtonLane a = StartNewtonLane(c0[i], c1[i], c2[i], c3[i], c4[i], c5[i]);
    NewtonLane b = StartNewtonLane(c0[j], c1[j], c2[j], c3[j], c4[j], c5[j]);
#pragma GCC unroll 8
    for (int it = 0; it < kNewtonSteps; ++it) {
      NewtonLaneStep(a);
      NewtonLaneStep(b);
    }
    FinishNewtonLane(a, relative_tolerance, out1[i], out2[i], out3[i], out_ok[i]);
    FinishNewtonLane(b, relative_tolerance, out1[j], out2[j], out3[j], out_ok[j]);
  }
  if (n % 2 == 1) {  // the last matrix alone
    const int i = n - 1;
    NewtonLane a = StartNewtonLane(c0[i], c1[i], c2[i], c3[i], c4[i], c5[i]);
    for (int it = 0; it < kNewtonSteps; ++it) NewtonLaneStep(a);
    FinishNewtonLane(a, relative_tolerance, out1[i], out2[i], out3[i], out_ok[i]);
  }
}

void NewtonBatchDefault(const double* const c[6], int n, double relative_tolerance, double* l1,
                        double* l2, double* l3, double* ok) {
  NewtonBatchLoop(c[0], c[1], c[2], c[3], c[4], c[5], n, relative_tolerance, l1, l2, l3, ok);
}

#ifdef PLANESLAM_X86
/// The same loop four lanes wide (its divisions and square roots dominate).
__attribute__((target("avx2,fma"))) void NewtonBatchAvx2(const double* const c[6], int n,
                                                         double relative_tolerance, double* l1,
                                                         double* l2, double* l3, double* ok) {
  NewtonBatchLoop(c[0], c[1], c[2], c[3], c[4], c[5], n, relative_tolerance, l1, l2, l3, ok);
}
#endif

}  // namespace

void SymEigenvaluesNewtonBatch(const double* const c[6], int n, double relative_tolerance,
                               double* l1, double* l2, double* l3, double* ok, SimdKernel kernel) {
#ifdef PLANESLAM_X86
  if (kernel == SimdKernel::kAvx2) {
    NewtonBatchAvx2(c, n, relative_tolerance, l1, l2, l3, ok);
    return;
  }
#endif
  NewtonBatchDefault(c, n, relative_tolerance, l1, l2, l3, ok);
}

namespace {

/// (x, y, z) with squared norm n replaces (best_x, best_y, best_z) when n > best (a select).
__attribute__((always_inline)) inline void TakeIfLonger(double n, double x, double y, double z,
                                                        double& best, double& best_x,
                                                        double& best_y, double& best_z) {
  const bool longer = n > best;
  best = longer ? n : best;
  best_x = longer ? x : best_x;
  best_y = longer ? y : best_y;
  best_z = longer ? z : best_z;
}

/// SmallestEigenvector for one matrix, without branches (selects only), so that the batch loop
/// below vectorises; the scalar function runs the same code.
__attribute__((always_inline)) inline void SmallestEigenvectorLane(double c0, double c1, double c2,
                                                                   double c3, double c4, double c5,
                                                                   double l1, double l2, double l3,
                                                                   double& vx, double& vy,
                                                                   double& vz, double& l1_refined) {
  // The rows of C - l1 I span the plane orthogonal to v1 (rank 2 when l1 < l2): the largest of the
  // three cross products is the best-conditioned estimate of v1.
  const double r0x = c0 - l1, r0y = c1, r0z = c2;
  const double r1x = c1, r1y = c3 - l1, r1z = c4;
  const double r2x = c2, r2y = c4, r2z = c5 - l1;
  const double a0 = r0y * r1z - r0z * r1y, a1 = r0z * r1x - r0x * r1z, a2 = r0x * r1y - r0y * r1x;
  const double b0 = r0y * r2z - r0z * r2y, b1 = r0z * r2x - r0x * r2z, b2 = r0x * r2y - r0y * r2x;
  const double d0 = r1y * r2z - r1z * r2y, d1 = r1z * r2x - r1x * r2z, d2 = r1x * r2y - r1y * r2x;
  const double na = a0 * a0 + a1 * a1 + a2 * a2, nb = b0 * b0 + b1 * b1 + b2 * b2,
               nd = d0 * d0 + d1 * d1 + d2 * d2;
  double best = na, x = a0, y = a1, z = a2;
  TakeIfLonger(nb, b0, b1, b2, best, x, y, z);
  TakeIfLonger(nd, d0, d1, d2, best, x, y, z);
  const double scale = std::max(std::abs(l3), std::abs(l1));
  const bool separated = best > 1e-28 * scale * scale * scale * scale && best > 0.0;
  const double inv = 1.0 / std::sqrt(separated ? best : 1.0);
  // l1 ~ l2 (collinear or isotropic points): any unit vector orthogonal to the largest row (the
  // zero vector when that is orthogonal to the axis picked, as Eigen's normalized() gives).
  const double n0 = r0x * r0x + r0y * r0y + r0z * r0z, n1 = r1x * r1x + r1y * r1y + r1z * r1z,
               n2 = r2x * r2x + r2y * r2y + r2z * r2z;
  double rn = n0, rx = r0x, ry = r0y, rz = r0z;
  TakeIfLonger(n1, r1x, r1y, r1z, rn, rx, ry, rz);
  TakeIfLonger(n2, r2x, r2y, r2z, rn, rx, ry, rz);
  const double ax = std::abs(rx) < 0.9 ? 1.0 : 0.0, ay = 1.0 - ax;   // UnitX or UnitY
  const double ox = -rz * ay, oy = rz * ax, oz = rx * ay - ry * ax;  // row x any
  const double on = ox * ox + oy * oy + oz * oz;
  const double oinv = on > 0.0 ? 1.0 / std::sqrt(on > 0.0 ? on : 1.0) : 1.0;
  const bool no_row = !(rn > 0.0);
  vx = separated ? x * inv : (no_row ? 0.0 : ox * oinv);
  vy = separated ? y * inv : (no_row ? 0.0 : oy * oinv);
  vz = separated ? z * inv : (no_row ? 1.0 : oz * oinv);
  // Rayleigh quotient: accurate smallest eigenvalue even when l1 << l3 (the trig form loses it to
  // cancellation at ~1e-16 l3).
  const double rq = c0 * vx * vx + c3 * vy * vy + c5 * vz * vz +
                    2.0 * (c1 * vx * vy + c2 * vx * vz + c4 * vy * vz);
  l1_refined = std::max(0.0, std::min(rq, l2));
}

__attribute__((always_inline)) inline void SmallestEigenvectorLoop(
    const double* __restrict c0, const double* __restrict c1, const double* __restrict c2,
    const double* __restrict c3, const double* __restrict c4, const double* __restrict c5,
    const double* __restrict l1, const double* __restrict l2, const double* __restrict l3, int n,
    double* __restrict vx, double* __restrict vy, double* __restrict vz,
    double* __restrict l1_refined) {
  for (int i = 0; i < n; ++i) {
    SmallestEigenvectorLane(c0[i], c1[i], c2[i], c3[i], c4[i], c5[i], l1[i], l2[i], l3[i], vx[i],
                            vy[i], vz[i], l1_refined[i]);
  }
}

void SmallestEigenvectorDefault(const double* const c[6], const double* l1, const double* l2,
                                const double* l3, int n, double* const v[3], double* l1_refined) {
  SmallestEigenvectorLoop(c[0], c[1], c[2], c[3], c[4], c[5], l1, l2, l3, n, v[0], v[1], v[2],
                          l1_refined);
}

#ifdef PLANESLAM_X86
__attribute__((target("avx2,fma"))) void SmallestEigenvectorAvx2(const double* const c[6],
                                                                 const double* l1, const double* l2,
                                                                 const double* l3, int n,
                                                                 double* const v[3],
                                                                 double* l1_refined) {
  SmallestEigenvectorLoop(c[0], c[1], c[2], c[3], c[4], c[5], l1, l2, l3, n, v[0], v[1], v[2],
                          l1_refined);
}
#endif

/// One grid of GridNoiseBatch, through MomentSums's own functions (scalars in and out, like
/// SmallestEigenvectorLane).
__attribute__((always_inline)) inline void GridNoiseLane(
    double k, double wxx, double wxy, double wxz, double wyy, double wyz, double wzz, double l2,
    double vx, double vy, double vz, double eta, double eta_sigmas, double& isotropic, double& tilt,
    double& effective, double& angle) {
  MomentSums m;
  m.k = k;
  m.wxx = wxx;
  m.wxy = wxy;
  m.wxz = wxz;
  m.wyy = wyy;
  m.wyz = wyz;
  m.wzz = wzz;
  // Locals, not the outputs read back (array elements, which kept the loop from vectorising).
  const double t = m.NormalTilt(l2);
  const double e = m.EffectiveMse(Eigen::Vector3d(vx, vy, vz), t);
  isotropic = m.IsotropicMse();
  tilt = t;
  effective = e;
  angle = eta + eta_sigmas * std::sqrt(e / std::max(l2, 1e-18));
}

__attribute__((always_inline)) inline void GridNoiseLoop(
    const double* __restrict k, const double* __restrict w0, const double* __restrict w1,
    const double* __restrict w2, const double* __restrict w3, const double* __restrict w4,
    const double* __restrict w5, const double* __restrict l2, const double* __restrict vx,
    const double* __restrict vy, const double* __restrict vz, int n, double eta, double eta_sigmas,
    double* __restrict isotropic, double* __restrict tilt, double* __restrict effective,
    double* __restrict angle) {
  for (int i = 0; i < n; ++i) {
    GridNoiseLane(k[i], w0[i], w1[i], w2[i], w3[i], w4[i], w5[i], l2[i], vx[i], vy[i], vz[i], eta,
                  eta_sigmas, isotropic[i], tilt[i], effective[i], angle[i]);
  }
}

void GridNoiseDefault(const double* k, const double* const w[6], const double* l2,
                      const double* const v[3], int n, double eta, double eta_sigmas,
                      double* isotropic, double* tilt, double* effective, double* angle) {
  GridNoiseLoop(k, w[0], w[1], w[2], w[3], w[4], w[5], l2, v[0], v[1], v[2], n, eta, eta_sigmas,
                isotropic, tilt, effective, angle);
}

#ifdef PLANESLAM_X86
__attribute__((target("avx2"))) void GridNoiseAvx2(const double* k, const double* const w[6],
                                                   const double* l2, const double* const v[3],
                                                   int n, double eta, double eta_sigmas,
                                                   double* isotropic, double* tilt,
                                                   double* effective, double* angle) {
  GridNoiseLoop(k, w[0], w[1], w[2], w[3], w[4], w[5], l2, v[0], v[1], v[2], n, eta, eta_sigmas,
                isotropic, tilt, effective, angle);
}
#endif

}  // namespace

void GridNoiseBatch(const double* k, const double* const w[6], const double* l2,
                    const double* const v[3], int n, double eta, double eta_sigmas,
                    double* isotropic, double* tilt, double* effective, double* angle,
                    SimdKernel kernel) {
#ifdef PLANESLAM_X86
  if (kernel == SimdKernel::kAvx2) {
    GridNoiseAvx2(k, w, l2, v, n, eta, eta_sigmas, isotropic, tilt, effective, angle);
    return;
  }
#endif
  GridNoiseDefault(k, w, l2, v, n, eta, eta_sigmas, isotropic, tilt, effective, angle);
}

void SmallestEigenvector(const double c[6], SymEigen3& e) {
  double x, y, z, l1;
  SmallestEigenvectorLane(c[0], c[1], c[2], c[3], c[4], c[5], e.l1, e.l2, e.l3, x, y, z, l1);
  e.v1 = Eigen::Vector3d(x, y, z);
  e.l1 = l1;
}

void SmallestEigenvectorBatch(const double* const c[6], const double* l1, const double* l2,
                              const double* l3, int n, double* const v[3], double* l1_refined,
                              SimdKernel kernel) {
#ifdef PLANESLAM_X86
  if (kernel == SimdKernel::kAvx2) {
    SmallestEigenvectorAvx2(c, l1, l2, l3, n, v, l1_refined);
    return;
  }
#endif
  SmallestEigenvectorDefault(c, l1, l2, l3, n, v, l1_refined);
}

void SymEigenvaluesAscending(const double c[6], double& l1, double& l2, double& l3) {
  if (!SymEigenvaluesNewton(c, 1e-14, l1, l2, l3)) SymEigenvalues3(c, l1, l2, l3);
}

SymEigen3 SymEigen3Smallest(const double c[6]) {
  SymEigen3 e;
  SymEigenvaluesAscending(c, e.l1, e.l2, e.l3);
  SmallestEigenvector(c, e);
  return e;
}

namespace {

/// The adjugate of C - shift I for a symmetric C (upper triangle c): its cofactors, symmetric as
/// well. adj(C - s I) = det(C - s I) (C - s I)^-1 without a division, so it stays defined when
/// C - s I is singular (exactly planar points, or s an eigenvalue): RefitFrom's power iteration.
struct SymAdjugate {
  double a00, a01, a02, a11, a12, a22;
  SymAdjugate(const double c[6], double shift) {
    const double d0 = c[0] - shift, d3 = c[3] - shift, d5 = c[5] - shift;
    a00 = d3 * d5 - c[4] * c[4];
    a01 = c[2] * c[4] - c[1] * d5;
    a02 = c[1] * c[4] - c[2] * d3;
    a11 = d0 * d5 - c[2] * c[2];
    a12 = c[1] * c[2] - d0 * c[4];
    a22 = d0 * d3 - c[1] * c[1];
  }
  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const {
    return Eigen::Vector3d(a00 * x.x() + a01 * x.y() + a02 * x.z(),
                           a01 * x.x() + a11 * x.y() + a12 * x.z(),
                           a02 * x.x() + a12 * x.y() + a22 * x.z());
  }
  /// The sum of C - s I's principal 2x2 minors (for s = 0, l1 l2 + l1 l3 + l2 l3).
  double Trace() const { return a00 + a11 + a22; }
};

}  // namespace

FastFit FitSums(const MomentSums& m) {
  FastFit f;
  if (m.k <= 0) return f;
  f.centroid = m.Centroid();
  if (m.k < 3) return f;
  double c[6];
  m.Scatter(c);
  const SymEigen3 e = SymEigen3Smallest(c);
  f.l1 = e.l1;
  f.l2 = std::max(0.0, e.l2);
  f.l3 = std::max(0.0, e.l3);
  Eigen::Vector3d n = e.v1;
  double d = n.dot(f.centroid);
  if (d < 0) {  // Hessian form with d >= 0: n points from the origin towards the plane
    n = -n;
    d = -d;
  }
  f.normal = n;
  f.d = d;
  f.mse = f.l1 / m.k;  // eq. (3)
  return f;
}

FastFit RefitFrom(const MomentSums& m, const Eigen::Vector3d& n0) {
  if (m.k < 3) return FitSums(m);
  double c[6];
  m.Scatter(c);
  const SymAdjugate adj(c, 0.0);
  const Eigen::Vector3d x0 = adj * (adj * n0);
  // Normalised once: adj C scales as C^2, so two steps stay far inside double range for any
  // point spread between 0.1 mm and kilometres.
  const double norm2 = x0.squaredNorm();
  if (!(norm2 > 1e-300) || !std::isfinite(norm2)) return FitSums(m);
  Eigen::Vector3d x = x0 / std::sqrt(norm2);
  auto rayleigh = [&c](const Eigen::Vector3d& v) {
    return std::max(0.0,
                    c[0] * v.x() * v.x() + c[3] * v.y() * v.y() + c[5] * v.z() * v.z() +
                        2.0 * (c[1] * v.x() * v.y() + c[2] * v.x() * v.z() + c[4] * v.y() * v.z()));
  };
  const double e2 = adj.Trace();  // l1 l2 + l1 l3 + l2 l3
  double l1 = 0, l2 = 0, l3 = 0;
  // l2 and l3 from l1 (the Rayleigh quotient of x), the trace and the second invariant.
  auto eigenvalues_from = [&](const Eigen::Vector3d& v) {
    l1 = rayleigh(v);
    const double s = c[0] + c[3] + c[5] - l1;  // l2 + l3
    const double p = e2 - l1 * s;              // l2 l3
    const double disc = std::sqrt(std::max(0.0, s * s - 4.0 * p));
    l3 = 0.5 * (s + disc);
    l2 = l3 > 0 ? p / l3 : 0.0;  // not (s - disc) / 2, which cancels when l2 << l3
  };
  eigenvalues_from(x);
  if (!(l1 <= 0.01 * l2)) {
    // Poorly separated (a young region, noisy grids): two steps on the adjugate of C - sigma I,
    // sigma the Rayleigh quotient (shifted inverse iteration without a division). Its factor per
    // step is (sigma - l1) / (l2 - sigma), about the square of x's angle from v1: from within
    // ~30 deg of it, 1e-8 rad after two steps. Then l1 <= l2 / 2 must hold, else (x went to v2,
    // or the plane is barely defined) the closed form decides. Most of GBRG's refits take this
    // path rather than the closed form.
    for (int it = 0; it < 2; ++it) {
      x = SymAdjugate(c, l1) * x;
      const double shifted_norm2 = x.squaredNorm();
      if (!(shifted_norm2 > 1e-300) || !std::isfinite(shifted_norm2)) return FitSums(m);
      x /= std::sqrt(shifted_norm2);
      l1 = rayleigh(x);
    }
    eigenvalues_from(x);
    if (!(l1 <= 0.5 * l2)) return FitSums(m);
  }
  FastFit f;
  f.centroid = m.Centroid();
  double d = x.dot(f.centroid);
  if (d < 0) {
    x = -x;
    d = -d;
  }
  f.normal = x;
  f.d = d;
  f.l1 = l1;
  f.l2 = std::max(0.0, l2);
  f.l3 = std::max(0.0, l3);
  f.mse = l1 / m.k;
  return f;
}

namespace {

#ifdef PLANESLAM_X86
/// The four points p[0], p[stride], p[2 stride], p[3 stride] (floats, 3 a point) as x, y, z
/// vectors of four lanes. Each load reads 16 bytes: the next point's x too (the caller makes sure
/// that one exists).
__attribute__((target("avx2,fma"))) inline void LoadFourPoints(const float* p, std::size_t stride,
                                                               __m128& x, __m128& y, __m128& z) {
  __m128 a = _mm_loadu_ps(p), b = _mm_loadu_ps(p + stride), c = _mm_loadu_ps(p + 2 * stride),
         d = _mm_loadu_ps(p + 3 * stride);
  _MM_TRANSPOSE4_PS(a, b, c, d);
  x = a;
  y = b;
  z = c;
}

/// Four vectors a, b, c, d (lane g: grid g) written as four consecutive doubles (a[g], b[g], c[g],
/// d[g]) at out[g * stride]: a 4 x 4 transpose in registers and four stores, instead of a store of
/// each lane.
__attribute__((target("avx2,fma"))) inline void StoreTransposed(__m256d a, __m256d b, __m256d c,
                                                                __m256d d, double* out,
                                                                std::size_t stride) {
  const __m256d ab_even = _mm256_unpacklo_pd(a, b), ab_odd = _mm256_unpackhi_pd(a, b);
  const __m256d cd_even = _mm256_unpacklo_pd(c, d), cd_odd = _mm256_unpackhi_pd(c, d);
  _mm256_storeu_pd(out, _mm256_permute2f128_pd(ab_even, cd_even, 0x20));
  _mm256_storeu_pd(out + stride, _mm256_permute2f128_pd(ab_odd, cd_odd, 0x20));
  _mm256_storeu_pd(out + 2 * stride, _mm256_permute2f128_pd(ab_even, cd_even, 0x31));
  _mm256_storeu_pd(out + 3 * stride, _mm256_permute2f128_pd(ab_odd, cd_odd, 0x31));
}

/// Lanes of a four-float mask widened to four doubles.
__attribute__((target("avx2,fma"))) inline __m256d WidenMask(__m128 mask) {
  return _mm256_castsi256_pd(_mm256_cvtepi32_epi64(_mm_castps_si128(mask)));
}

/// SumPixelBlock of four neighbouring k x k grids at once, one grid a lane: the grids whose
/// first columns are x0, x0 + k, x0 + 2k, x0 + 3k, rows [y0, y1). Each lane adds its pixels in the
/// scalar kernel's order; invalid pixels add zeros (masked) instead of being skipped. The moments
/// and the ray sums take a pass each (with 10 and 9 accumulators, each fits the 16 registers).
/// One copy per sensor model and ray weighting: with both tests inside the ray pass's loop the
/// compiler keeps five of its nine accumulators on the stack (a load and a store per accumulator
/// and pixel); the Kinect copy keeps all in registers.
template <bool kSpherical, bool kUniformWeight>
__attribute__((target("avx2,fma"))) void SumFourGridsAvx2(const Eigen::Vector3f* points, int width,
                                                          int x0, int y0, int y1, int k,
                                                          const DetectionParams& params,
                                                          MomentSums* sums, RaySums* rays) {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "points are packed float triples");
  static_assert(std::is_standard_layout_v<MomentSums> &&
                    sizeof(MomentSums) == 16 * sizeof(double) && offsetof(MomentSums, k) == 0 &&
                    offsetof(MomentSums, zz) == 9 * sizeof(double),
                "grid sums are stored as 16 doubles, k first, then S, Q, W");
  static_assert(std::is_standard_layout_v<RaySums> && sizeof(RaySums) == 9 * sizeof(double) &&
                    offsetof(RaySums, a00) == 0 && offsetof(RaySums, b2) == 8 * sizeof(double),
                "ray sums are stored as 9 doubles, a00 first, b2 last");
  const float* base = reinterpret_cast<const float*>(points);
  const std::size_t lane_stride = 3 * static_cast<std::size_t>(k);
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 one = _mm_set1_ps(1.0f);
  // Lane 0's pixel (y, x0 + j); lane g's is k points further.
  auto index = [&](int y, int j) { return static_cast<std::size_t>(y) * width + x0 + j; };
  {
    __m256d n = _mm256_setzero_pd(), sx = n, sy = n, sz = n, xx = n, xy = n, xz = n, yy = n, yz = n,
            zz = n;
    for (int y = y0; y < y1; ++y) {
      for (int j = 0; j < k; ++j) {
        __m128 xf, yf, zf;
        LoadFourPoints(base + 3 * index(y, j), lane_stride, xf, yf, zf);
        const __m128 valid = _mm_cmplt_ps(_mm_and_ps(zf, abs_mask), inf);  // finite z
        const __m256d x = _mm256_cvtps_pd(_mm_and_ps(xf, valid));
        const __m256d yv = _mm256_cvtps_pd(_mm_and_ps(yf, valid));
        const __m256d z = _mm256_cvtps_pd(_mm_and_ps(zf, valid));
        n = _mm256_add_pd(n, _mm256_cvtps_pd(_mm_and_ps(one, valid)));
        sx = _mm256_add_pd(sx, x);
        sy = _mm256_add_pd(sy, yv);
        sz = _mm256_add_pd(sz, z);
        xx = _mm256_fmadd_pd(x, x, xx);
        xy = _mm256_fmadd_pd(x, yv, xy);
        xz = _mm256_fmadd_pd(x, z, xz);
        yy = _mm256_fmadd_pd(yv, yv, yy);
        yz = _mm256_fmadd_pd(yv, z, yz);
        zz = _mm256_fmadd_pd(z, z, zz);
      }
    }
    // Each grid's 16 sums (W zero) in four transposes, not lane by lane through memory.
    double* const out = reinterpret_cast<double*>(sums);
    const std::size_t stride = sizeof(MomentSums) / sizeof(double);
    const __m256d zero = _mm256_setzero_pd();
    StoreTransposed(n, sx, sy, sz, out, stride);
    StoreTransposed(xx, xy, xz, yy, out + 4, stride);
    StoreTransposed(yz, zz, zero, zero, out + 8, stride);
    StoreTransposed(zero, zero, zero, zero, out + 12, stride);
  }
  if (rays == nullptr) return;
  const __m256d s0 = _mm256_set1_pd(params.sigma0), s2 = _mm256_set1_pd(params.sigma_z2);
  __m256d a00 = _mm256_setzero_pd(), a01 = a00, a02 = a00, a11 = a00, a12 = a00, a22 = a00,
          b0 = a00, b1 = a00, b2 = a00;
  for (int y = y0; y < y1; ++y) {
    for (int j = 0; j < k; ++j) {
      __m128 xf, yf, zf;
      LoadFourPoints(base + 3 * index(y, j), lane_stride, xf, yf, zf);
      const __m128 valid = _mm_cmplt_ps(_mm_and_ps(zf, abs_mask), inf);
      // The depth s (the range as internal::PointDepth forms it, lane by lane) and the ray p / s
      // in float, as RaySums::Add; pixels at s <= 0 (or NaN) add nothing.
      __m128 s = zf;
      if constexpr (kSpherical) {
        // The range, four lanes at once: internal::PointDepth's float operations in Eigen's
        // order, sqrt(x x + (y y + z z)), so the same values.
        s = _mm_sqrt_ps(_mm_add_ps(_mm_mul_ps(xf, xf),
                                   _mm_add_ps(_mm_mul_ps(yf, yf), _mm_mul_ps(zf, zf))));
      }
      const __m128 use = _mm_and_ps(valid, _mm_cmpgt_ps(s, _mm_setzero_ps()));
      const __m128 inv_f = _mm_and_ps(_mm_div_ps(one, s), use);
      const __m256d qx = _mm256_cvtps_pd(_mm_mul_ps(_mm_and_ps(xf, use), inv_f));
      const __m256d qy = _mm256_cvtps_pd(_mm_mul_ps(_mm_and_ps(yf, use), inv_f));
      const __m256d qz = _mm256_cvtps_pd(_mm_mul_ps(_mm_and_ps(zf, use), inv_f));
      const __m256d inv = _mm256_cvtps_pd(inv_f);
      __m256d wx = qx, wy = qy, wz = qz;
      if constexpr (!kUniformWeight) {
        // DetectionParams::InverseDepthWeight: (s^2 / sigma)^2, 1 where sigma <= 0.
        const __m256d sd = _mm256_cvtps_pd(_mm_and_ps(s, use));
        const __m256d sigma = _mm256_fmadd_pd(_mm256_mul_pd(s2, sd), sd, s0);
        const __m256d t = _mm256_div_pd(_mm256_mul_pd(sd, sd), sigma);
        __m256d w = _mm256_blendv_pd(_mm256_set1_pd(1.0), _mm256_mul_pd(t, t),
                                     _mm256_cmp_pd(sigma, _mm256_setzero_pd(), _CMP_GT_OQ));
        w = _mm256_and_pd(w, WidenMask(use));
        wx = _mm256_mul_pd(w, qx);
        wy = _mm256_mul_pd(w, qy);
        wz = _mm256_mul_pd(w, qz);
      }
      a00 = _mm256_fmadd_pd(wx, qx, a00);
      a01 = _mm256_fmadd_pd(wx, qy, a01);
      a02 = _mm256_fmadd_pd(wx, qz, a02);
      a11 = _mm256_fmadd_pd(wy, qy, a11);
      a12 = _mm256_fmadd_pd(wy, qz, a12);
      a22 = _mm256_fmadd_pd(wz, qz, a22);
      b0 = _mm256_fmadd_pd(wx, inv, b0);
      b1 = _mm256_fmadd_pd(wy, inv, b1);
      b2 = _mm256_fmadd_pd(wz, inv, b2);
    }
  }
  double* const out = reinterpret_cast<double*>(rays);
  const std::size_t stride = sizeof(RaySums) / sizeof(double);
  StoreTransposed(a00, a01, a02, a11, out, stride);
  StoreTransposed(a12, a22, b0, b1, out + 4, stride);
  const __m128d b2_low = _mm256_castpd256_pd128(b2), b2_high = _mm256_extractf128_pd(b2, 1);
  _mm_storel_pd(out + 8, b2_low);
  _mm_storeh_pd(out + 8 + stride, b2_low);
  _mm_storel_pd(out + 8 + 2 * stride, b2_high);
  _mm_storeh_pd(out + 8 + 3 * stride, b2_high);
}
#endif

}  // namespace

#ifdef PLANESLAM_X86
namespace {
__attribute__((target("avx2"))) std::size_t MapLabelsAvx2(const std::int32_t* shifted_table,
                                                          const std::int32_t* in, std::int32_t* out,
                                                          std::size_t n) {
  const __m256i one = _mm256_set1_epi32(1);
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256i index =
        _mm256_add_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(in + i)), one);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + i),
                        _mm256_i32gather_epi32(shifted_table, index, 4));
  }
  return i;
}
}  // namespace
#endif

void MapLabels(const std::int32_t* shifted_table, const std::int32_t* in, std::int32_t* out,
               std::size_t n, SimdKernel kernel) {
  std::size_t i = 0;
#ifdef PLANESLAM_X86
  if (kernel == SimdKernel::kAvx2) i = MapLabelsAvx2(shifted_table, in, out, n);
#else
  (void)kernel;
#endif
  for (; i < n; ++i) out[i] = shifted_table[in[i] + 1];
}

SimdKernel FastestSimdKernel() {
#ifdef PLANESLAM_X86
  static const bool avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return avx2 ? SimdKernel::kAvx2 : SimdKernel::kScalar;
#else
  return SimdKernel::kScalar;
#endif
}

void SumPixelBlock(const Eigen::Vector3f* points, int width, int x0, int y0, int x1, int y1,
                   bool spherical, const DetectionParams& params, MomentSums& m, RaySums* rays) {
  for (int y = y0; y < y1; ++y) {
    const Eigen::Vector3f* row = points + static_cast<std::size_t>(y) * width;
    for (int x = x0; x < x1; ++x) {
      const Eigen::Vector3f& p = row[x];
      if (!std::isfinite(p.z())) continue;
      m.AddPosition(p.x(), p.y(), p.z());
      if (rays == nullptr) continue;
      const float s = internal::PointDepth(p, spherical);
      if (s > 0.0f) rays->Add(p, s, params.RayFitWeight(s));
    }
  }
}

void SumGridRow(const Eigen::Vector3f* points, int width, int height, int y0, int y1, int k,
                bool spherical, const DetectionParams& params, MomentSums* sums, RaySums* rays,
                SimdKernel kernel, const MomentSums* next_sums, const RaySums* next_rays) {
  const int cells = (width + k - 1) / k;
  int cx = 0;
#ifdef PLANESLAM_X86
  if (kernel == SimdKernel::kAvx2) {
    const bool uniform_weight = params.sigma0 == 0.0;  // RayFitWeight is 1
    auto* const sum_four_grids =
        spherical
            ? (uniform_weight ? &SumFourGridsAvx2<true, true> : &SumFourGridsAvx2<true, false>)
            : (uniform_weight ? &SumFourGridsAvx2<false, true> : &SumFourGridsAvx2<false, false>);
    // Groups of four whole grids whose loads (16 bytes a point) stay inside the cloud.
    const std::size_t num_points = static_cast<std::size_t>(width) * height;
    for (; cx + 4 <= cells; cx += 4) {
      const int x0 = cx * k;
      if (x0 + 4 * k > width) break;
      const std::size_t last = static_cast<std::size_t>(y1 - 1) * width + x0 + 4 * k - 1;
      if (last + 1 >= num_points) break;
      // The same columns of the next band of rows, fetched while this band is summed: when the
      // memory is busy this stage waits on the cloud (12 bytes a pixel), and the hardware
      // prefetcher, following k rows at once, does not run far enough ahead. One band ahead is
      // enough; further ahead the lines are evicted before use.
      const std::size_t next_band = static_cast<std::size_t>(y1) * width + x0;
      for (int y = 0; y < y1 - y0; ++y) {
        const std::size_t first = next_band + static_cast<std::size_t>(y) * width;
        if (first + 4 * static_cast<std::size_t>(k) > num_points) break;
        const char* row = reinterpret_cast<const char*>(points + first);
        for (int byte = 0; byte < 12 * 4 * k; byte += 64) __builtin_prefetch(row + byte);
      }
      // The next row's sums of the same four grids, fetched for writing: a store to a line that
      // is not in the cache waits for it to be read first, and the megabytes of sums of 3x3
      // grids are not, a frame later. One row ahead: two rows ahead evicts more than it saves.
      if (next_sums != nullptr) {
        const char* line = reinterpret_cast<const char*>(next_sums + cx);
        for (std::size_t b = 0; b < 4 * sizeof(MomentSums); b += 64)
          __builtin_prefetch(line + b, 1);
      }
      if (next_rays != nullptr) {
        const char* line = reinterpret_cast<const char*>(next_rays + cx);
        for (std::size_t b = 0; b < 4 * sizeof(RaySums) + 63; b += 64) {
          __builtin_prefetch(line + b, 1);
        }
      }
      sum_four_grids(points, width, x0, y0, y1, k, params, sums + cx,
                     rays != nullptr ? rays + cx : nullptr);
    }
  }
#endif
  for (; cx < cells; ++cx) {
    const int x0 = cx * k, x1 = std::min(width, x0 + k);
    sums[cx] = MomentSums();
    RaySums* r = rays != nullptr ? rays + cx : nullptr;
    if (r != nullptr) *r = RaySums();
    SumPixelBlock(points, width, x0, y0, x1, y1, spherical, params, sums[cx], r);
  }
}

}  // namespace planeslam::detection

#pragma once
// Helpers shared by the registration tests: random motions, planes with consistent noise.
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>
#include <random>

#include "planeslam/detection/plane.hpp"
#include "planeslam/registration/geometry.hpp"

namespace planeslam::registration::test {

// Every random draw below is its own statement: the order in which a compiler evaluates function
// arguments or operands is unspecified, and gcc and clang differ, which would give the sanitizer
// build (clang) other scenes than the normal build (gcc).

inline Eigen::Vector3d RandomUnit(std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) v(i) = g(rng);
  return v.normalized();
}

/// A random rigid motion with |t| <= max_t and rotation angle <= max_angle.
inline Pose RandomPose(std::mt19937& rng, double max_t, double max_angle) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Pose T = Pose::Identity();
  const Eigen::Vector3d axis = RandomUnit(rng);
  const double angle = max_angle * u(rng);
  T.linear() = ExpSO3(axis * angle);
  const Eigen::Vector3d direction = RandomUnit(rng);
  T.translation() = direction * max_t * u(rng);
  return T;
}

/// A noise-free plane n.p = d, oriented so that d >= 0, reporting a covariance of sigma_n [rad]
/// isotropic in the normal's tangent plane and sigma_d [m] on the offset.
inline detection::Plane MakePlane(const Eigen::Vector3d& n, double d, double sigma_n = 0.001,
                                  double sigma_d = 0.005) {
  detection::Plane p;
  p.normal = n.normalized();
  p.d = d;
  if (p.d < 0) {
    p.normal = -p.normal;
    p.d = -p.d;
  }
  p.centroid = p.normal * p.d;
  p.point_count = 1000;
  p.covariance.setZero();
  p.covariance.topLeftCorner<3, 3>() =
      sigma_n * sigma_n * (Eigen::Matrix3d::Identity() - p.normal * p.normal.transpose());
  p.covariance(3, 3) = sigma_d * sigma_d;
  return p;
}

/// A random plane with a random normal and its offset drawn from `offset` (see MakePlane).
template <typename Distribution>
detection::Plane RandomPlane(std::mt19937& rng, Distribution& offset) {
  const Eigen::Vector3d n = RandomUnit(rng);
  return MakePlane(n, offset(rng));
}

/// Plane b moved into frame a by T_a_b (noise-free), with the d >= 0 orientation kept.
inline detection::Plane MovePlane(const detection::Plane& b, const Pose& T_a_b) {
  const PlaneParams q = TransformPlane(T_a_b, b.normal, b.d);
  detection::Plane p = MakePlane(q.normal, q.d);
  p.centroid = T_a_b * b.centroid;
  return p;
}

/// A random SPD 3x3 covariance over (tangent1, tangent2, d) with normal sigmas in
/// [sn_lo, sn_hi] rad, offset sigma in [sd_lo, sd_hi] m and random correlations.
inline Eigen::Matrix3d RandomPlaneNoise(std::mt19937& rng, double sn_lo, double sn_hi, double sd_lo,
                                        double sd_hi) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::uniform_real_distribution<double> c(-0.6, 0.6);
  const Eigen::Vector3d sig(sn_lo + (sn_hi - sn_lo) * u(rng), sn_lo + (sn_hi - sn_lo) * u(rng),
                            sd_lo + (sd_hi - sd_lo) * u(rng));
  Eigen::Matrix3d corr = Eigen::Matrix3d::Identity();
  corr(0, 1) = corr(1, 0) = c(rng) * 0.5;
  corr(0, 2) = corr(2, 0) = c(rng);
  corr(1, 2) = corr(2, 1) = c(rng);
  // Keep it positive definite: blend with the identity until the Cholesky succeeds.
  while (corr.llt().info() != Eigen::Success || corr.determinant() < 0.05) {
    corr = 0.5 * (corr + Eigen::Matrix3d::Identity());
  }
  return sig.asDiagonal() * corr * sig.asDiagonal();
}

/// Adds noise drawn from `s` (tangent1, tangent2, d coordinates at the true normal) to a plane
/// and sets the plane's 4x4 (n, d) covariance to the same distribution expressed at the noisy
/// normal, as a detector would report it.
inline detection::Plane AddPlaneNoise(const detection::Plane& truth, const Eigen::Matrix3d& s,
                                      std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  const Eigen::Matrix3d L = s.llt().matrixL();
  Eigen::Vector3d z;
  for (int i = 0; i < 3; ++i) z(i) = g(rng);
  const Eigen::Vector3d e = L * z;
  const Eigen::Matrix<double, 3, 2> u = TangentBasis(truth.normal);
  detection::Plane p = truth;
  p.normal = (truth.normal + u * e.head<2>()).normalized();
  p.d = truth.d + e(2);
  const Eigen::Matrix<double, 3, 2> u_noisy = TangentBasis(p.normal);
  // Express the tangent coordinates in the noisy normal's basis (same plane to first order).
  const Eigen::Matrix2d rot = u_noisy.transpose() * u;
  Eigen::Matrix3d s_noisy = s;
  s_noisy.topLeftCorner<2, 2>() = rot * s.topLeftCorner<2, 2>() * rot.transpose();
  s_noisy.topRightCorner<2, 1>() = rot * s.topRightCorner<2, 1>();
  s_noisy.bottomLeftCorner<1, 2>() = s_noisy.topRightCorner<2, 1>().transpose();
  Eigen::Matrix<double, 4, 3> b = Eigen::Matrix<double, 4, 3>::Zero();
  b.topLeftCorner<3, 2>() = u_noisy;
  b(3, 2) = 1.0;
  p.covariance = b * s_noisy * b.transpose();
  return p;
}

/// Angle between two rotations [rad] and distance between translations [m].
inline double RotationError(const Pose& a, const Pose& b) {
  return LogSO3(a.linear() * b.linear().transpose()).norm();
}
inline double TranslationError(const Pose& a, const Pose& b) {
  return (a.translation() - b.translation()).norm();
}

}  // namespace planeslam::registration::test

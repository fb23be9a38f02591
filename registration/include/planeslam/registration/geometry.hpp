#pragma once
/// Small SO(3)/SE(3) helpers and the plane transform shared by the registration code.
///
/// Tangent convention used everywhere in planeslam::registration (6-vectors, translation first):
///   delta = (dt_x, dt_y, dt_z, dtheta_x, dtheta_y, dtheta_z),
///   BoxPlus((R, t), delta) = (Exp(dtheta) * R, t + dt),
/// i.e. translation is additive and rotation is a LEFT perturbation, both expressed in the frame
/// the pose maps INTO (for T_prev_curr: the previous frame). This is exactly the error of Ceres'
/// examples/slam/pose_graph_3d residual [t_est - t_meas; 2 vec(q_meas * q_est^-1)] to first
/// order, so a covariance from here can be inverted and used there without conversion.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::registration {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// [v]_x: Skew(v) * w = v x w.
inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

/// Rotation matrix of the rotation vector w (Rodrigues).
inline Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-12) return Eigen::Matrix3d::Identity() + Skew(w);
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

/// Rotation vector of R (angle in [0, pi]); goes through a quaternion, stable near 0 and pi.
inline Eigen::Vector3d LogSO3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(Eigen::Quaterniond(R).normalized());
  return aa.angle() * aa.axis();
}

/// (Exp(dtheta) R, t + dt); see the tangent convention above.
inline Pose BoxPlus(const Pose& T, const Vector6d& delta) {
  Pose out = Pose::Identity();
  out.linear() = ExpSO3(delta.tail<3>()) * T.linear();
  out.translation() = T.translation() + delta.head<3>();
  return out;
}

/// delta with BoxPlus(T_ref, delta) == T.
inline Vector6d BoxMinus(const Pose& T, const Pose& T_ref) {
  Vector6d d;
  d.head<3>() = T.translation() - T_ref.translation();
  d.tail<3>() = LogSO3(T.linear() * T_ref.linear().transpose());
  return d;
}

/// An orthonormal basis (3x2) of the plane orthogonal to the unit vector n.
inline Eigen::Matrix<double, 3, 2> TangentBasis(const Eigen::Vector3d& n) {
  // Cross with the axis least aligned with n: never near-parallel, so no cancellation.
  Eigen::Index axis = 0;
  n.cwiseAbs().minCoeff(&axis);
  const Eigen::Vector3d e1 = n.cross(Eigen::Vector3d::Unit(axis)).normalized();
  Eigen::Matrix<double, 3, 2> u;
  u.col(0) = e1;
  u.col(1) = n.cross(e1);
  return u;
}

/// A plane (n, d) with n.p = d expressed in frame b, mapped to frame a by p_a = R p_b + t:
/// n_a = R n_b, d_a = d_b + n_a . t. The sign is kept (d_a may come out negative).
struct PlaneParams {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double d = 0.0;
};
inline PlaneParams TransformPlane(const Pose& T_a_b, const Eigen::Vector3d& n_b, double d_b) {
  PlaneParams out;
  out.normal = T_a_b.linear() * n_b;
  out.d = d_b + out.normal.dot(T_a_b.translation());
  return out;
}
/// Jacobian of TransformPlane's (n_a, d_a) with respect to (n_b, d_b): [[R, 0], [t^T R, 1]].
inline Eigen::Matrix4d TransformPlaneJacobian(const Pose& T_a_b) {
  Eigen::Matrix4d j = Eigen::Matrix4d::Zero();
  j.topLeftCorner<3, 3>() = T_a_b.linear();
  j.bottomLeftCorner<1, 3>() = T_a_b.translation().transpose() * T_a_b.linear();
  j(3, 3) = 1.0;
  return j;
}

/// The lower Cholesky factor L (A = L L^T) of a symmetric 3x3 A, written out: Eigen's LLT
/// solves a matrix right-hand side with its general blocked kernel, which costs more than the
/// factorisation itself at this size. False when A is not positive definite.
inline bool Cholesky3(const Eigen::Matrix3d& A, Eigen::Matrix3d* L) {
  if (!(A(0, 0) > 0)) return false;
  const double l00 = std::sqrt(A(0, 0));
  const double l10 = A(1, 0) / l00, l20 = A(2, 0) / l00;
  const double d1 = A(1, 1) - l10 * l10;
  if (!(d1 > 0)) return false;
  const double l11 = std::sqrt(d1);
  const double l21 = (A(2, 1) - l20 * l10) / l11;
  const double d2 = A(2, 2) - l20 * l20 - l21 * l21;
  if (!(d2 > 0)) return false;
  *L << l00, 0, 0, l10, l11, 0, l20, l21, std::sqrt(d2);
  return true;
}

/// A^-1 = L^-T L^-1 from A's Cholesky factor L.
inline Eigen::Matrix3d InverseFromCholesky3(const Eigen::Matrix3d& L) {
  Eigen::Matrix3d Li = Eigen::Matrix3d::Zero();  // L^-1, lower triangular
  Li(0, 0) = 1.0 / L(0, 0);
  Li(1, 1) = 1.0 / L(1, 1);
  Li(2, 2) = 1.0 / L(2, 2);
  Li(1, 0) = -L(1, 0) * Li(0, 0) * Li(1, 1);
  Li(2, 1) = -L(2, 1) * Li(1, 1) * Li(2, 2);
  Li(2, 0) = -(L(2, 0) * Li(0, 0) + L(2, 1) * Li(1, 0)) * Li(2, 2);
  return Li.transpose() * Li;
}

}  // namespace planeslam::registration

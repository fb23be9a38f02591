#pragma once
// Private: the per-match plane residual shared by registration and association.
#include <Eigen/Core>
#include <cmath>
#include <vector>

#include "planeslam/registration/plane_registration.hpp"

namespace planeslam::registration::internal {

/// One match with its planes in the form the residual needs.
struct MatchData {
  PlaneMatch match;
  Eigen::Vector3d n_a = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d n_b = Eigen::Vector3d::UnitZ();
  double d_a = 0.0;
  double d_b = 0.0;
  Eigen::Matrix4d cov_a = Eigen::Matrix4d::Zero();  ///< (n, d) covariance, scaled
  Eigen::Matrix4d cov_b = Eigen::Matrix4d::Zero();
  Eigen::Matrix<double, 3, 2> tangent;  ///< orthonormal basis orthogonal to n_a
};

/// Residual r (3), its Jacobian over (dt, dtheta), its covariance and inverse.
struct Linearized {
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d W = Eigen::Matrix3d::Identity();
};

/// The lower Cholesky factor L (A = L L^T) of a symmetric 3x3 A, written out: Eigen's LLT
/// solves a matrix right-hand side with its general blocked kernel, which costs more than the
/// factorisation itself at this size. False when A is not positive definite.
inline bool Cholesky3(const Eigen::Matrix3d& A, Eigen::Matrix3d* L) {
  const double l00 = A(0, 0) > 0 ? std::sqrt(A(0, 0)) : 0.0;
  if (!(l00 > 0)) return false;
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

/// False when either plane is unusable (non-finite); CheckError on bad indices.
bool MakeMatchData(const std::vector<detection::Plane>& prev,
                   const std::vector<detection::Plane>& curr, const PlaneMatch& match,
                   const RegistrationConfig& config, MatchData* out);

Linearized Linearize(const MatchData& m, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                     const RegistrationConfig& config);

/// RegisterPlanes on matches already in residual form (those RegisterPlanes would keep, in the
/// order of its matches): the association solves many subsets of one candidate set.
RegistrationResult RegisterMatchData(const std::vector<MatchData>& data, const MotionPrior& prior,
                                     const RegistrationConfig& config);

}  // namespace planeslam::registration::internal

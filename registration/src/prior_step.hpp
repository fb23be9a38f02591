#pragma once
// Private: what the fills of open directions share (point_to_plane.cpp, depth_local_map.cpp,
// local_map.cpp, plane_extent.cpp): the input check, the prior's information, the regularised
// Gauss-Newton step along a set of directions with a Gaussian prior on their coefficients, and
// the count of directions still left to the prior.
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

namespace planeslam::registration::internal {

/// A direction of the tangent (6-vector, geometry.hpp) without a rotation part.
inline bool IsTranslation(const Eigen::VectorXd& dir) { return dir.tail<3>().norm() < 1e-9; }

/// The prior's count of translation directions after a fill measured the columns `keep` of `D`:
/// their translations leave it, and it stays within [0, prior_directions] (the count after the
/// fill), since two fills of one frame may measure the same direction.
inline int PriorTranslationsAfter(int prior_translations, int prior_directions,
                                  const Eigen::MatrixXd& D, const std::vector<int>& keep) {
  for (int i : keep) prior_translations -= IsTranslation(D.col(i)) ? 1 : 0;
  return std::clamp(prior_translations, 0, std::max(prior_directions, 0));
}

/// chi^2(m) 99.9% quantile by Wilson-Hilferty: m (1 - 2/(9m) + 3.09 sqrt(2/(9m)))^3.
inline double Chi2Quantile999(double m) {
  return m * std::pow(1.0 - 2.0 / (9.0 * m) + 3.09 * std::sqrt(2.0 / (9.0 * m)), 3);
}

/// Whether an aligner can run along `D` (6 x k, k >= 1, finite) with a k x k prior covariance.
inline bool DirectionsUsable(const Eigen::MatrixXd& D, const Eigen::MatrixXd& prior_covariance) {
  const Eigen::Index k = D.cols();
  return k > 0 && D.rows() == 6 && prior_covariance.rows() == k &&
         prior_covariance.cols() == k && D.allFinite();
}

/// The prior's information: the inverse of the covariance's symmetric part, or zero (no prior)
/// when that is not finite and positive definite.
inline Eigen::MatrixXd PriorInformation(const Eigen::MatrixXd& prior_covariance) {
  const Eigen::Index k = prior_covariance.rows();
  const Eigen::MatrixXd s = 0.5 * (prior_covariance + prior_covariance.transpose());
  if (!s.allFinite()) return Eigen::MatrixXd::Zero(k, k);
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(s);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return Eigen::MatrixXd::Zero(k, k);
  Eigen::MatrixXd inv = ldlt.solve(Eigen::MatrixXd::Identity(k, k));
  return inv.allFinite() ? inv : Eigen::MatrixXd::Zero(k, k);
}

/// One Gauss-Newton step of the coefficients y with the prior N(0, h_prior^-1) on them: the
/// pairs' information H and gradient g (of their cost, at y) give A = H + h_prior, and
/// step = -A^-1 (g + h_prior y), covariance = A^-1, both from one LDLT factorisation. With no
/// prior and no structure A may be singular: a ridge of 1e-12 of its largest diagonal keeps the
/// step defined (those directions do not move). False (nothing written) on a non-finite step.
inline bool PriorStep(const Eigen::MatrixXd& H, const Eigen::VectorXd& g,
                      const Eigen::MatrixXd& h_prior, const Eigen::VectorXd& y,
                      Eigen::VectorXd* step, Eigen::MatrixXd* covariance) {
  const Eigen::Index k = H.rows();
  Eigen::MatrixXd A = H + h_prior;
  A.diagonal().array() += 1e-12 * std::max(1.0, A.diagonal().maxCoeff());
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
  Eigen::VectorXd s = ldlt.solve(-(g + h_prior * y));
  if (!s.allFinite()) return false;
  *step = std::move(s);
  *covariance = ldlt.solve(Eigen::MatrixXd::Identity(k, k));
  return true;
}

}  // namespace planeslam::registration::internal

#pragma once
// Private: the per-match plane residual shared by registration and association.
#include <Eigen/Core>
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

/// Residual r (3), its Jacobian over (dt, dtheta) and its covariance.
struct Linearized {
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Identity();
};

/// False when either plane is unusable (non-finite); CheckError on bad indices.
bool MakeMatchData(const std::vector<detection::Plane>& prev,
                   const std::vector<detection::Plane>& curr, const PlaneMatch& match,
                   const RegistrationConfig& config, MatchData* out);

Linearized Linearize(const MatchData& m, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                     const RegistrationConfig& config);

/// The residual's information matrix, cov^-1 (only the least squares weigh by it; the other
/// callers of Linearize read cov).
Eigen::Matrix3d ResidualWeight(const Eigen::Matrix3d& cov, const RegistrationConfig& config);

/// RegisterPlanes on matches already in residual form (those RegisterPlanes would keep, in the
/// order of its matches): the association solves many subsets of one candidate set.
RegistrationResult RegisterMatchData(const std::vector<MatchData>& data, const MotionPrior& prior,
                                     const RegistrationConfig& config);

}  // namespace planeslam::registration::internal

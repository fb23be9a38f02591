#pragma once
// Helpers shared by the SlamSystem sources (slam_system.cpp, slam_closures.cpp).
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <chrono>
#include <cmath>

#include "planeslam/mapping/pose_graph.hpp"

namespace planeslam::mapping::slam_internal {

inline constexpr double kDegToRad = M_PI / 180.0;

inline double ElapsedMs(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since)
      .count();
}

inline double RotationAngle(const Pose& T) { return Eigen::AngleAxisd(T.rotation()).angle(); }

inline Matrix6d DiagonalCovariance(double translation_sigma, double rotation_sigma) {
  Vector6d diag;
  diag << Eigen::Vector3d::Constant(translation_sigma * translation_sigma),
      Eigen::Vector3d::Constant(rotation_sigma * rotation_sigma);
  return diag.asDiagonal();
}

/// Edge information from a registration covariance. Registration reports (dt, dtheta) in the
/// previous frame with additive translation and left-perturbed rotation, which is exactly the
/// pose-graph residual's parameterisation (q_a^-1 (p_b - p_a) - p_ab; 2 vec(q_meas q_est^-1)).
inline Matrix6d InformationFromCovariance(const Matrix6d& covariance) {
  Matrix6d symmetric = 0.5 * (covariance + covariance.transpose());
  Matrix6d information = symmetric.ldlt().solve(Matrix6d::Identity());
  information = 0.5 * (information + information.transpose());
  // Guard against a numerically indefinite result: floor the spectrum.
  Eigen::SelfAdjointEigenSolver<Matrix6d> eig(information);
  const Vector6d values = eig.eigenvalues().cwiseMax(1e-6);
  return eig.eigenvectors() * values.asDiagonal() * eig.eigenvectors().transpose();
}

}  // namespace planeslam::mapping::slam_internal

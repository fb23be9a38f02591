// Re-acquisition of the map after the planes left directions of the motion open: the frame's
// planes are associated with the map's by a gate in Mahalanobis distance under the uncertainty
// the open directions accumulated, and the pose is pulled back onto the map (SlamSystem::
// Reacquire in slam_system.hpp).
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>

#include "planeslam/mapping/slam_system.hpp"
#include "slam_internal.hpp"

namespace planeslam::mapping {

using namespace slam_internal;  // NOLINT: the helpers shared by the SlamSystem sources

namespace {

/// A detected plane paired with a map plane: the detection (sensor frame) and the map plane
/// (world), with the detection's offset variance.
struct PlanePair {
  Eigen::Vector3d normal_sensor;
  double d_sensor = 0.0;
  Eigen::Vector3d normal_world;
  double d_world = 0.0;
  double offset_variance = 0.0;  ///< [m^2]
  double normal_variance = 0.0;  ///< per tangent axis [rad^2]
};

/// Residuals of one pair at T_world_sensor: the detection moved into the world against the map
/// plane, offset first, then the normal's difference (3), and their Jacobians with respect to
/// the world-frame correction (dt, dtheta) of T (t <- t + dt, R <- Exp(dtheta) R).
void PairResidual(const PlanePair& p, const Pose& T, Eigen::Vector4d* r,
                  Eigen::Matrix<double, 4, 6>* J) {
  const Eigen::Vector3d n = T.linear() * p.normal_sensor;
  const Eigen::Vector3d t = T.translation();
  (*r)(0) = p.d_sensor + n.dot(t) - p.d_world;
  r->tail<3>() = n - p.normal_world;
  J->setZero();
  // d(n . t) = n . dt + (dtheta x n) . t = n . dt + dtheta . (n x t).
  J->block<1, 3>(0, 0) = n.transpose();
  J->block<1, 3>(0, 3) = n.cross(t).transpose();
  // d n = dtheta x n = -[n]_x dtheta.
  J->block<3, 3>(1, 3) = -registration::Skew(n);
}

}  // namespace

bool SlamSystem::Reacquire(const detection::Segmentation& segmentation, std::int64_t keyframe_id,
                           Pose* T_world_sensor, Pose* T_keyframe_curr, Matrix6d* covariance) {
  if (!(config_.reacquire_translation_sigma > 0)) return false;
  const Eigen::Matrix3d translation_cov = drift_covariance_.topLeftCorner<3, 3>();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(translation_cov);
  if (!(std::sqrt(std::max(eig.eigenvalues().maxCoeff(), 0.0)) >
        config_.reacquire_translation_sigma)) {
    return false;
  }
  ++stats_.reacquisition_attempts;
  const Pose T0 = *T_world_sensor;
  const double normal_variance = config_.landmark_normal_sigma * config_.landmark_normal_sigma;
  // Association: each detection with the map plane whose offset and normal agree with it under
  // the drift (its covariance propagated to the pair's residual, plus both planes' own noise):
  // chi^2 of 3 dof (offset and the normal's two tangent angles) within 99.9%, and the runner-up
  // at least 4 (2 sigma in one direction) farther off; an ambiguous detection is left out.
  std::vector<PlanePair> pairs;
  for (const detection::Plane& plane : segmentation.planes) {
    const double own = std::max(plane.covariance(3, 3),
                                config_.landmark_offset_sigma * config_.landmark_offset_sigma);
    double best = std::numeric_limits<double>::infinity(), second = best;
    PlanePair chosen;
    for (const MapPlane& m : map_.planes()) {
      const PlanePair pair{plane.normal, plane.d, m.normal, m.d, own, normal_variance};
      Eigen::Vector4d r;
      Eigen::Matrix<double, 4, 6> J;
      PairResidual(pair, T0, &r, &J);
      if (r.tail<3>().norm() > 1.0) continue;  // more than 60 degrees apart: not this plane
      Eigen::Vector4d own_variance;
      own_variance << 2.0 * own, Eigen::Vector3d::Constant(2.0 * normal_variance);
      const Eigen::Matrix4d S =
          J * drift_covariance_ * J.transpose() + Eigen::Matrix4d(own_variance.asDiagonal());
      const double chi2 = r.dot(S.ldlt().solve(r));
      if (chi2 < best) {
        second = best;
        best = chi2;
        chosen = pair;
      } else if (chi2 < second) {
        second = chi2;
      }
    }
    if (best <= 16.27 && second > best + 4.0) pairs.push_back(chosen);
  }
  if (pairs.size() < 2) return false;

  // Gauss-Newton on the correction with the drift as its prior (floored: the directions the
  // planes held are not exactly known either).
  Matrix6d prior = drift_covariance_ + DiagonalCovariance(0.005, 0.2 * kDegToRad);
  const Matrix6d prior_information = InformationFromCovariance(prior);
  Pose T = T0;
  Matrix6d H = Matrix6d::Zero();
  for (int it = 0; it < 5; ++it) {
    H = prior_information;
    Vector6d g = prior_information * registration::BoxMinus(T, T0);
    for (const PlanePair& p : pairs) {
      Eigen::Vector4d r;
      Eigen::Matrix<double, 4, 6> J;
      PairResidual(p, T, &r, &J);
      Eigen::Vector4d w;
      w << 1.0 / p.offset_variance, Eigen::Vector3d::Constant(1.0 / p.normal_variance);
      H += J.transpose() * w.asDiagonal() * J;
      g += J.transpose() * w.asDiagonal() * r;
    }
    const Vector6d step = -H.ldlt().solve(g);
    if (!step.allFinite()) return false;
    T = registration::BoxPlus(T, step);
    if (step.norm() < 1e-7) break;
  }
  // Every pair must agree with the corrected pose (3 sigma on its offset), the correction must be
  // plausible under the drift (chi^2 of 6 dof, 99.9%), and the map must pin the drift down.
  for (const PlanePair& p : pairs) {
    Eigen::Vector4d r;
    Eigen::Matrix<double, 4, 6> J;
    PairResidual(p, T, &r, &J);
    if (r(0) * r(0) > 9.0 * p.offset_variance) return false;
  }
  const Vector6d change = registration::BoxMinus(T, T0);
  if (!(change.dot(prior_information * change) <= 22.46)) return false;
  const Matrix6d posterior = H.ldlt().solve(Matrix6d::Identity());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> after(posterior.topLeftCorner<3, 3>());
  if (!(std::sqrt(std::max(after.eigenvalues().maxCoeff(), 0.0)) <
        config_.reacquire_translation_sigma)) {
    return false;
  }
  *T_world_sensor = T;
  const Pose T_world_keyframe = KeyframePose(keyframe_id);
  *T_keyframe_curr = T_world_keyframe.inverse() * T;
  Matrix6d R = Matrix6d::Zero();
  R.topLeftCorner<3, 3>() = T_world_keyframe.linear();
  R.bottomRightCorner<3, 3>() = T_world_keyframe.linear();
  *covariance += R.transpose() * drift_covariance_ * R;
  drift_covariance_.setZero();
  ++stats_.reacquisitions;
  return true;
}

}  // namespace planeslam::mapping

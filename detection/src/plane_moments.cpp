#include "planeslam/detection/plane_moments.hpp"

#include <Eigen/Eigenvalues>

namespace planeslam::detection {

void PlaneMoments::Add(const Eigen::Vector3d& p) {
  if (count_ == 0 && reference_.isZero()) reference_ = p;
  const Eigen::Vector3d q = p - reference_;
  ++count_;
  sum_ += q;
  sum_sq_.noalias() += q * q.transpose();
}

PlaneMoments PlaneMoments::FromSums(std::int64_t count, const Eigen::Vector3d& sum,
                                    const Eigen::Matrix3d& sum_sq,
                                    const Eigen::Vector3d& reference) {
  PlaneMoments m(reference);
  m.count_ = count;
  m.sum_ = sum;
  m.sum_sq_ = sum_sq;
  return m;
}

void PlaneMoments::Merge(const PlaneMoments& other) {
  if (other.count_ == 0) return;
  if (count_ == 0) {
    *this = other;
    return;
  }
  // Re-express the other's sums relative to our reference: with q' = q + delta,
  // sum q' = S + K delta and sum q' q'^T = Q + S delta^T + delta S^T + K delta delta^T.
  const Eigen::Vector3d delta = other.reference_ - reference_;
  const double k = static_cast<double>(other.count_);
  sum_sq_ += other.sum_sq_ + other.sum_ * delta.transpose() + delta * other.sum_.transpose() +
             k * delta * delta.transpose();
  sum_ += other.sum_ + k * delta;
  count_ += other.count_;
}

Eigen::Vector3d PlaneMoments::Centroid() const {
  if (count_ == 0) return reference_;
  return reference_ + sum_ / static_cast<double>(count_);
}

Eigen::Matrix3d PlaneMoments::Scatter() const {
  if (count_ == 0) return Eigen::Matrix3d::Zero();
  const Eigen::Vector3d mean = sum_ / static_cast<double>(count_);
  // Eq. (6): C = Q - S m^T, in reference-relative coordinates (C is translation invariant).
  return sum_sq_ - sum_ * mean.transpose();
}

PlaneFit PlaneMoments::Fit() const {
  PlaneFit fit;
  fit.centroid = Centroid();
  if (count_ < 3) return fit;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(Scatter());
  fit.eigenvalues = solver.eigenvalues().cwiseMax(0.0);  // ascending; clamp round-off below zero
  Eigen::Vector3d n = solver.eigenvectors().col(0).normalized();
  double d = n.dot(fit.centroid);
  if (d < 0) {  // Hessian form with d >= 0: the normal points from the origin towards the plane
    n = -n;
    d = -d;
  }
  fit.normal = n;
  fit.d = d;
  fit.mse = fit.eigenvalues(0) / static_cast<double>(count_);
  fit.valid = n.allFinite();
  return fit;
}

double PlaneMoments::MseWith(const PlaneMoments& extra) const {
  PlaneMoments merged = *this;
  merged.Merge(extra);
  return merged.Fit().mse;
}

}  // namespace planeslam::detection

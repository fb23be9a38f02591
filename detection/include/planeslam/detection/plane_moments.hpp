#pragma once
/// Sufficient statistics of a point set and the least-squares plane they define (paper eq. 3-6).
#include <Eigen/Core>
#include <cstdint>

namespace planeslam::detection {

/// Result of fitting a plane to moments.
struct PlaneFit {
  Eigen::Vector3d normal =
      Eigen::Vector3d::Zero();  ///< unit, oriented towards the sensor side: d >= 0
  double d = 0.0;               ///< offset [m], n.p = d
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();     ///< mass centre m = S/K [m]
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();  ///< of C, ascending [m^2]
  double mse = 0.0;    ///< lambda_min / K [m^2] (eq. 5; eq. 4's missing /K is a slip)
  bool valid = false;  ///< false with fewer than 3 points
};

/// K, S = sum p, Q = sum p p^T, accumulated in double relative to a reference point so that
/// C = Q - S m^T (eq. 6) does not lose precision to cancellation far from the origin.
/// Add and Merge are O(1); Merge of two sets equals the moments of their union.
class PlaneMoments {
 public:
  PlaneMoments() = default;
  /// Moments with an explicit reference point (e.g. the first point of a region).
  explicit PlaneMoments(const Eigen::Vector3d& reference) : reference_(reference) {}

  void Add(const Eigen::Vector3d& p);
  void Add(const Eigen::Vector3f& p) { Add(Eigen::Vector3d(p.cast<double>())); }
  void Merge(const PlaneMoments& other);
  void Clear() { *this = PlaneMoments(reference_); }
  /// Moments from raw sums taken relative to `reference`: K, sum (p - ref), sum (p - ref)(p -
  /// ref)^T.
  static PlaneMoments FromSums(std::int64_t count, const Eigen::Vector3d& sum,
                               const Eigen::Matrix3d& sum_sq,
                               const Eigen::Vector3d& reference = Eigen::Vector3d::Zero());

  std::int64_t count() const { return count_; }
  /// Mass centre S/K in world coordinates.
  Eigen::Vector3d Centroid() const;
  /// Scatter matrix C = sum (p - m)(p - m)^T.
  Eigen::Matrix3d Scatter() const;
  /// Plane fit from the smallest eigenpair of C (closed-form 3x3 solver).
  PlaneFit Fit() const;
  /// MSE of the plane fitted to these moments plus `extra` (without modifying either).
  double MseWith(const PlaneMoments& extra) const;
  /// Reference point the sums are taken about.
  const Eigen::Vector3d& reference() const { return reference_; }
  /// sum (p - reference) [m].
  const Eigen::Vector3d& sum() const { return sum_; }
  /// sum (p - reference)(p - reference)^T [m^2].
  const Eigen::Matrix3d& sum_sq() const { return sum_sq_; }

 private:
  Eigen::Vector3d reference_ = Eigen::Vector3d::Zero();
  std::int64_t count_ = 0;
  Eigen::Vector3d sum_ = Eigen::Vector3d::Zero();     ///< sum (p - reference)
  Eigen::Matrix3d sum_sq_ = Eigen::Matrix3d::Zero();  ///< sum (p - reference)(p - reference)^T
};

}  // namespace planeslam::detection

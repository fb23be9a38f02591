#include "planeslam/mapping/loop_registration.hpp"

#include <algorithm>

#include "slam_internal.hpp"

namespace planeslam::mapping {

using slam_internal::DiagonalCovariance;
using slam_internal::InformationFromCovariance;

registration::RegistrationResult AnchoredLoopRegistration(
    const std::vector<detection::Plane>& old_planes,
    const std::vector<detection::Plane>& current_planes, const Pose& T_old_current,
    const LoopRegistrationConfig& config) {
  registration::MotionPrior prior;
  prior.T_prev_curr = T_old_current;
  prior.covariance =
      DiagonalCovariance(config.prior_translation_sigma, config.prior_rotation_sigma);
  return registration::AssociatePlanes(old_planes, current_planes, prior, config.association,
                                       config.registration)
      .registration;
}

registration::RegistrationResult UnanchoredLoopRegistration(
    const std::vector<detection::Plane>& old_planes,
    const std::vector<detection::Plane>& current_planes, const Pose& T_old_current,
    const LoopRegistrationConfig& config) {
  registration::AssociationConfig free_config = config.association;
  free_config.max_offset_difference =
      std::max(config.association.max_offset_difference, config.search_radius);
  free_config.prior_gate_chi2 = 0.0;
  registration::MotionPrior prior;
  prior.T_prev_curr = T_old_current;
  prior.covariance = DiagonalCovariance(config.search_radius, config.prior_rotation_sigma);
  return registration::AssociatePlanes(old_planes, current_planes, prior, free_config,
                                       config.registration)
      .registration;
}

double RegistrationDifferenceChi2(const registration::RegistrationResult& a,
                                  const registration::RegistrationResult& b) {
  const Vector6d difference = registration::BoxMinus(b.T_prev_curr, a.T_prev_curr);
  return difference.dot(InformationFromCovariance(a.covariance + b.covariance) * difference);
}

bool UnanchoredRivalsAnchored(const registration::RegistrationResult& anchored,
                              const registration::RegistrationResult& unanchored, double chi2) {
  return unanchored.converged && unanchored.inliers.size() >= anchored.inliers.size() &&
         RegistrationDifferenceChi2(anchored, unanchored) > chi2;
}

}  // namespace planeslam::mapping

#pragma once
/// A loop candidate's planes registered twice (SlamSystem::SearchLoopClosures): anchored on the
/// trajectory estimate, whose offset gate keeps the search near where the estimate puts the
/// partners, and unanchored, whose gates admit any partner within the search radius. After a
/// drift, the anchored search can pair a plane with a parallel one at the drift's distance (a
/// wall with a cabinet front, the road with a surface a metre above it) and find a solution that
/// merely confirms the drift; the unanchored one then tells it apart.
#include <vector>

#include "planeslam/detection/plane.hpp"
#include "planeslam/registration/plane_association.hpp"

namespace planeslam::mapping {

struct LoopRegistrationConfig {
  double prior_translation_sigma = 0.3;  ///< [m] the estimate's anchor (slam.loop_prior_*)
  double prior_rotation_sigma = 0.15;    ///< [rad]
  double search_radius = 1.5;            ///< [m] slam.loop_search_radius
  registration::AssociationConfig association;
  registration::RegistrationConfig registration;
};

/// The old keyframe's planes associated with the current one's around the estimate's relative
/// pose T_old_current (sigmas of the anchor, the association's own gates).
registration::RegistrationResult AnchoredLoopRegistration(
    const std::vector<detection::Plane>& old_planes,
    const std::vector<detection::Plane>& current_planes, const Pose& T_old_current,
    const LoopRegistrationConfig& config);

/// The same planes associated without the anchor: offsets gated by the search radius only, no
/// preference for the estimate; the most supported consistent set wins.
registration::RegistrationResult UnanchoredLoopRegistration(
    const std::vector<detection::Plane>& old_planes,
    const std::vector<detection::Plane>& current_planes, const Pose& T_old_current,
    const LoopRegistrationConfig& config);

/// Chi-square (6 dof) of the difference of two registrations under their summed covariances.
double RegistrationDifferenceChi2(const registration::RegistrationResult& a,
                                  const registration::RegistrationResult& b);

/// Whether the unanchored solution shows that the anchored one was picked by the estimate's gate
/// rather than by the planes: it converged, at least as many plane pairs support it, and it lies
/// elsewhere beyond the two covariances (chi-square above `chi2`). It need not pass the closure's
/// own checks to count: the planes admit a solution the anchored search could not see, so the
/// anchored one is no measurement of the loop.
bool UnanchoredRivalsAnchored(const registration::RegistrationResult& anchored,
                              const registration::RegistrationResult& unanchored, double chi2);

}  // namespace planeslam::mapping

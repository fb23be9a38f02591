#pragma once
/// Plane correspondences between two frames without knowing them in advance (Pathak et al.,
/// T-RO 2010, in the spirit of their minimally-uncertain maximal-consensus search).
///
/// 1. Candidates (i in prev, j in curr) gated by the angle between n_prev and R_prior n_curr, the
///    offset difference after the prior motion, and the ratio of in-plane extents.
/// 2. Two candidates are consistent when a rigid motion could explain both: the angle between
///    the two normals is the same in both frames, and for (anti)parallel pairs the offset
///    difference (sum) is the same up to what the prior translation can change.
/// 3. The largest sets of mutually consistent candidates (maximum cliques, branch and bound with
///    a colouring bound, node budget), and the set grown from the matches the motion prior
///    predicts, are verified (solve, drop matches with a large residual, add gated candidates
///    that fit); the one kept agrees with the prior if any does, then has the most support (each
///    match weighs as its smaller plane's pixel count: consensus counted in evidence rather than
///    in planes, so a few small facets of a curved surface that agree on a wrong motion do not
///    outvote two walls), then the fewest degenerate directions, then the smallest pose
///    uncertainty (log det of the covariance).
#include <vector>

#include "planeslam/detection/plane.hpp"
#include "planeslam/registration/plane_registration.hpp"

namespace planeslam::registration {

/// Parameters of the association. Angles in degrees, distances in metres.
struct AssociationConfig {
  double max_normal_angle_deg = 20.0;  ///< gate: angle(n_prev, R_prior n_curr) [deg]
  double max_offset_difference = 0.3;  ///< gate: |d_prev - d_curr predicted by the prior| [m]
  /// Gate on the ratio of the larger to the smaller in-plane extent (sqrt of the largest scatter
  /// eigenvalue over K); 0 disables it. Partial views change extents, hence a loose value [-].
  double max_extent_ratio = 6.0;
  /// Pairwise check: the angles between two normals may differ by this much between frames
  /// (added in quadrature to 3 sigma from the planes' covariances) [deg].
  double pair_angle_tolerance_deg = 3.0;
  /// Normals closer than this to parallel or antiparallel also compare offsets [deg].
  double parallel_angle_deg = 10.0;
  /// Pairwise check on the offset difference of (anti)parallel pairs (plus 3 sigma) [m].
  double pair_offset_tolerance = 0.05;
  /// Current planes closer than this to the sensor are also tried with the opposite
  /// orientation (the sign of n is arbitrary for a plane through the origin) [m].
  double flip_max_offset = 0.05;
  int max_candidates_per_plane = 6;  ///< keep the best-gated candidates of each prev plane [-]
  int max_tied_cliques = 16;         ///< maximum cliques verified for the tie-break [-]
  int max_search_nodes = 20000;      ///< branch-and-bound budget [-]
  /// Verification gate on a match's whitened residual (3 dof; 99.9% of chi^2(3) = 16.27) [-].
  double inlier_chi2 = 16.27;
  /// A solution whose motion differs from the prior by more than this chi^2 (6 dof, with both
  /// covariances; 99.9% of chi^2(6) = 22.46) loses to any that agrees with it; 0 = no check [-].
  double prior_gate_chi2 = 22.46;

  std::vector<std::string> Validate() const;
};

struct AssociationResult {
  std::vector<PlaneMatch> matches;  ///< verified, one-to-one
  int candidates = 0;               ///< after gating
  int clique_size = 0;              ///< size of the maximum consistent set
  int tied_cliques = 0;             ///< maximum cliques found with that size (up to the limit)
  bool search_exhausted = false;    ///< node budget hit: the clique may not be maximum
  bool prior_inconsistent = false;  ///< even the best solution disagrees with the prior
  /// Registration of the chosen matches (what the tie-break computed); callers may re-run it.
  RegistrationResult registration;
};

/// Matches the planes of two frames. Deterministic; any input (no planes, one plane, all
/// parallel) gives a result without throwing.
AssociationResult AssociatePlanes(const std::vector<detection::Plane>& prev,
                                  const std::vector<detection::Plane>& curr,
                                  const MotionPrior& prior, const AssociationConfig& config = {},
                                  const RegistrationConfig& registration_config = {});

/// The matches whose planes agree with `motion`'s prediction: the current plane moved into the
/// previous frame by T_prev_curr against the previous plane, the angle between their normals (two
/// components) and the difference of their offsets whitened by both planes' covariances (scaled
/// and floored as registration does) and the motion's; their sum must stay within the 99.9 %
/// quantile of chi-square with 2 dof (14.1, under the 16.3 of 3 dof: about 0.3 % of true pairs
/// fall outside under an exact noise model). A match outside it, where the others agree, pairs
/// two different planes (a small plane with another).
std::vector<PlaneMatch> PlausibleMatches(const std::vector<detection::Plane>& prev,
                                         const std::vector<detection::Plane>& curr,
                                         const std::vector<PlaneMatch>& matches,
                                         const MotionPrior& motion,
                                         const RegistrationConfig& config = {});

}  // namespace planeslam::registration

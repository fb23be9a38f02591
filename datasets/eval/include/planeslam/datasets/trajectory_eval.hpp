#pragma once
/// Trajectory evaluation: time association, Umeyama alignment, APE and RPE, error statistics.
///
/// Two families of semantics, each reproduced exactly (see the definitions below):
///  - evo (MichaelGrupp/evo: core/sync.py, core/geometry.py, core/trajectory.py, core/metrics.py,
///    core/filters.py): nearest-stamp association of the shorter trajectory within 0.01 s, no
///    alignment unless asked, RPE E = inv(Q_i⁻¹ Q_j) (P_i⁻¹ P_j) with delta in frames by default.
///  - the TUM RGB-D benchmark tools (associate.py, evaluate_ate.py, evaluate_rpe.py): one-to-one
///    association within 0.02 s closest first, ATE always aligned (Horn), RPE on the raw files with
///    E = inv(P_j⁻¹ P_i) (Q_j⁻¹ Q_i) (P estimate, Q ground truth).
/// Q / ref is the reference (ground truth), P / est the estimate. Pure computation, no printing.
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

/// (reference index, estimate index).
using IndexPair = std::pair<std::size_t, std::size_t>;

// ---------------------------------------------------------------------------------------------
// Association

/// evo's rule (sync.associate_trajectories): for each stamp of the shorter trajectory (the estimate
/// when both have the same length) the nearest stamp of the other (first one on ties), kept when
/// |t_ref - (t_est + offset)| <= max_diff. Not one to one: a stamp of the longer trajectory can be
/// used twice. Pairs come in increasing time.
std::vector<IndexPair> AssociateNearest(const std::vector<double>& ref_stamps,
                                        const std::vector<double>& est_stamps,
                                        double max_diff = 0.01, double offset = 0.0);

/// The TUM tool's rule (associate.py): all pairs with |t_ref - (t_est + offset)| < max_diff,
/// taken closest first (ties by reference then estimate stamp), each stamp used once; sorted by
/// reference stamp.
std::vector<IndexPair> AssociateTum(const std::vector<double>& ref_stamps,
                                    const std::vector<double>& est_stamps, double max_diff = 0.02,
                                    double offset = 0.0);

/// Pairs (i, i) for i < min(n_ref, n_est): KITTI files have no stamps.
std::vector<IndexPair> AssociateByIndex(std::size_t n_ref, std::size_t n_est);

struct AssociationOptions {
  enum class Method { kNearest, kTum, kIndex };
  Method method = Method::kNearest;
  double max_diff = 0.01;  ///< [s] evo's --t_max_diff (TUM: 0.02 and strict)
  double offset = 0.0;     ///< [s] added to the estimate's stamps
};

/// Associates by `options`; throws IoError(est_name, reason) when no pair is found (no overlap in
/// time, or stamps in different clocks), or when index pairing meets different lengths.
std::vector<IndexPair> AssociateTrajectories(const Trajectory& ref, const Trajectory& est,
                                             const AssociationOptions& options,
                                             const std::string& ref_name = "reference",
                                             const std::string& est_name = "estimate");

// ---------------------------------------------------------------------------------------------
// Alignment

/// y = scale * rotation * x + translation.
struct Sim3Transform {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;
};

struct UmeyamaResult {
  Sim3Transform transform;
  bool degenerate = false;  ///< fewer than 3 points, or collinear: rotation not determined
  std::string reason;
  Eigen::Vector3d singular_values = Eigen::Vector3d::Zero();  ///< of the cross-covariance
};

/// Least-squares Sim(3) (or SE(3) when !with_scale) taking `source` onto `target` (Umeyama 1991,
/// eqs. 34-43, as evo's geometry.umeyama_alignment). Degenerate when the cross-covariance has rank
/// < 2 (second singular value <= 1e-12 x the first): collinear or coincident points.
UmeyamaResult UmeyamaAlignment(const Eigen::Matrix3Xd& source, const Eigen::Matrix3Xd& target,
                               bool with_scale);

struct AlignmentOptions {
  bool align = false;          ///< SE(3) Umeyama (evo -a)
  bool correct_scale = false;  ///< with align: Sim(3) (evo -as); alone: scale only (evo -s)
  bool align_origin = false;   ///< make the first poses coincide (after the above, as evo)
  int n_to_align = -1;         ///< use only the first N pairs for Umeyama (-1 = all)
};

struct AlignmentResult {
  bool degenerate = false;
  std::string reason;
  bool used_umeyama = false;
  Sim3Transform umeyama;  ///< as applied (rotation/translation identity in scale-only)
  bool used_origin = false;
  Pose origin = Pose::Identity();  ///< T applied on the left by --align-origin
};

/// Aligns `est` (associated with `ref`, same length) in place, in evo's order: Umeyama (SE(3),
/// Sim(3) or scale only) then origin alignment. On a degenerate input `est` is left unchanged
/// and the result says why.
AlignmentResult AlignTrajectory(const std::vector<Pose>& ref, std::vector<Pose>& est,
                                const AlignmentOptions& options);

// ---------------------------------------------------------------------------------------------
// Errors and statistics

enum class PoseRelation {
  kTranslation,       ///< "trans_part": ‖t_E‖ [m]
  kRotationAngleDeg,  ///< "angle_deg": angle of R_E [deg]
  kRotationAngleRad,  ///< "angle_rad": angle of R_E [rad]
  kRotationPart,      ///< "rot_part": ‖R_E - I‖_F (unit-less)
  kFull,              ///< "full": ‖E - I‖_F over the 4x4 matrix (unit-less)
};

/// "trans_part", "angle_deg", "angle_rad", "rot_part", "full".
std::string ToString(PoseRelation relation);
/// Parses the names above; throws ConfigError otherwise.
PoseRelation ParsePoseRelation(const std::string& name);
/// evo's wording: "translation part", "rotation angle in degrees", ...
std::string Description(PoseRelation relation);
/// "m", "deg", "rad" or "unit-less".
std::string UnitOf(PoseRelation relation);

/// Rotation angle in [0, pi] of a rotation matrix, atan2(‖vee(R - Rᵀ)‖, tr R - 1) (accurate near
/// 0 and pi, unlike acos).
double RotationAngle(const Eigen::Matrix3d& rotation);

/// The error value of an error pose E for `relation`.
double ErrorOf(const Pose& error_pose, PoseRelation relation);

/// evo's statistics; std is the population one (ddof 0), median averages the middle two.
struct ErrorStatistics {
  double rmse = 0, mean = 0, median = 0, std = 0, min = 0, max = 0, sse = 0;
  std::size_t count = 0;
};
/// Statistics of `errors` (all zero with count 0 when empty).
ErrorStatistics ComputeStatistics(const std::vector<double>& errors);

/// APE of associated poses (same length): translation_part is ‖t_est - t_ref‖, the others use
/// E = est⁻¹ ref as evo's ape_base.
std::vector<double> ApeErrors(const std::vector<Pose>& ref, const std::vector<Pose>& est,
                              PoseRelation relation);

enum class DeltaUnit { kFrames, kMeters, kDegrees, kRadians, kSeconds };
/// "f", "m", "deg", "rad", "s"; throws ConfigError otherwise.
DeltaUnit ParseDeltaUnit(const std::string& name);
std::string ToString(DeltaUnit unit);

/// evo's pair selection (metrics.id_pairs_from_delta over the estimate's poses): frames, path
/// length [m] or accumulated rotation [deg|rad]; consecutive non-overlapping pairs, or every pair
/// within rel_tol x delta with all_pairs. Seconds are not an evo unit (empty result).
std::vector<IndexPair> EvoRpePairs(const std::vector<Pose>& poses, double delta, DeltaUnit unit,
                                   double rel_tol = 0.1, bool all_pairs = false);

/// evo's RPE error pose: E = inv(Q_i⁻¹ Q_j) (P_i⁻¹ P_j).
Pose EvoRelativeError(const Pose& q_i, const Pose& q_j, const Pose& p_i, const Pose& p_j);

/// The TUM tool's error pose: E = inv(P_j⁻¹ P_i) (Q_j⁻¹ Q_i), with the estimate's relative
/// translation multiplied by `scale` (its --scale).
Pose TumRelativeError(const Pose& q_i, const Pose& q_j, const Pose& p_i, const Pose& p_j,
                      double scale = 1.0);

/// evaluate_rpe.py's find_closest_index: its binary search over a sorted list, kept verbatim in
/// behaviour (returns the best of the visited midpoints).
std::size_t TumFindClosestIndex(const std::vector<double>& sorted, double value);

// ---------------------------------------------------------------------------------------------
// Whole evaluations (what `planeslam eval` runs)

struct ApeOptions {
  AssociationOptions association;
  AlignmentOptions alignment;
  PoseRelation relation = PoseRelation::kTranslation;
  double scale = 1.0;  ///< estimate positions multiplied by this first (evaluate_ate.py --scale)
};

struct ApeResult {
  bool ok = false;  ///< false: alignment degenerate (see message)
  std::string message;
  std::vector<IndexPair> pairs;  ///< into the input trajectories
  std::vector<double> stamps;    ///< estimate stamps of the pairs [s]
  std::vector<Pose> ref_poses;   ///< associated reference poses
  std::vector<Pose> est_poses;   ///< associated estimate poses after alignment
  AlignmentResult alignment;
  std::vector<double> errors;
  ErrorStatistics stats;
};

/// Associate, align, compute APE. Throws IoError when nothing associates (see
/// AssociateTrajectories). evaluate_ate.py is association kTum with max_diff 0.02 plus align.
ApeResult EvaluateApe(const Trajectory& ref, const Trajectory& est, const ApeOptions& options,
                      const std::string& ref_name = "reference",
                      const std::string& est_name = "estimate");

struct RpeOptions {
  AssociationOptions association;  ///< evo mode only
  AlignmentOptions alignment;      ///< applied before pairing (matters with a scale)
  PoseRelation relation = PoseRelation::kTranslation;
  double delta = 1.0;
  DeltaUnit delta_unit = DeltaUnit::kFrames;
  bool all_pairs = false;
  double rel_delta_tol = 0.1;  ///< evo's all-pairs tolerance, relative to delta

  bool tum = false;               ///< evaluate_rpe.py semantics instead of evo's
  bool fixed_delta = false;       ///< TUM --fixed_delta; else all pairs, or random ones
  std::size_t max_pairs = 10000;  ///< TUM --max_pairs (0 = all)
  double scale = 1.0;             ///< TUM --scale
  std::uint32_t seed = 0;         ///< for TUM's random pair sampling (its own RNG is not seeded)
};

struct RpeResult {
  bool ok = false;
  std::string message;
  /// Pairs of indices: evo mode into the associated lists (ref_poses/est_poses), TUM mode into
  /// the estimate file (est_pairs) and the ground-truth file (ref_pairs).
  std::vector<IndexPair> est_pairs;
  std::vector<IndexPair> ref_pairs;
  std::vector<double> stamps;   ///< estimate stamp of the second pose of each pair [s]
  std::vector<Pose> ref_poses;  ///< evo mode: associated reference; TUM mode: whole ground truth
  std::vector<Pose> est_poses;  ///< evo mode: associated aligned estimate; TUM: whole estimate
  AlignmentResult alignment;
  std::vector<double> errors;  ///< for options.relation
  ErrorStatistics stats;
  /// Both parts, as evaluate_rpe.py prints them (translation [m], rotation [deg]).
  std::vector<double> trans_errors, rot_errors_deg;
  ErrorStatistics trans_stats, rot_stats_deg;
};

/// RPE with evo's or the TUM tool's semantics. Throws IoError when nothing associates.
RpeResult EvaluateRpe(const Trajectory& ref, const Trajectory& est, const RpeOptions& options,
                      const std::string& ref_name = "reference",
                      const std::string& est_name = "estimate");

}  // namespace planeslam::datasets

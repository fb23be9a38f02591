#pragma once
/// Offline plane SLAM: frame-to-keyframe plane tracking, a keyframe pose graph with verified loop
/// closures, and the global plane map.
///
/// Per frame: the detector's planes are associated with the current keyframe's planes (prior:
/// constant velocity) and registered in closed form (registration module); directions the planes
/// leave open (a corridor's axis) are filled by point-to-plane alignment of the clouds where they
/// can be. The pose of a frame is kept relative to its keyframe (T_kf_frame), so every frame
/// follows its keyframe when the graph is optimised. A new keyframe starts when the motion since
/// the keyframe passes a threshold or the planes shared with it get few; it adds a node, an
/// odometry edge weighted by the registration's covariance, its planes to the map, and a
/// loop-closure search: nearby keyframes (by the current estimate) that are not recent are
/// registered against it with the estimated relative pose as prior; only a non-degenerate,
/// consistent, small-residual registration enters the graph (with a robust loss), after which the
/// graph is optimised and the map re-fitted.
#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/detection/plane.hpp"
#include "planeslam/mapping/closure_consistency.hpp"
#include "planeslam/mapping/plane_map.hpp"
#include "planeslam/mapping/pose_graph.hpp"
#include "planeslam/mapping/view_bins.hpp"
#include "planeslam/registration/depth_local_map.hpp"
#include "planeslam/registration/local_map.hpp"
#include "planeslam/registration/plane_association.hpp"
#include "planeslam/registration/plane_extent.hpp"
#include "planeslam/registration/plane_registration.hpp"
#include "planeslam/registration/point_to_plane.hpp"
#include "planeslam/registration/velocity_model.hpp"

namespace planeslam::mapping {

/// Keyframe and loop-closure settings (YAML section "slam").
struct SlamConfig {
  double keyframe_translation = 0.20;   ///< [m] new keyframe after this motion since the last one
  double keyframe_rotation_deg = 12.0;  ///< [deg] same for rotation
  /// [planes] new keyframe when fewer planes match the keyframe and the frame has planes the
  /// keyframe does not match. Three matched planes are often two walls and a box face, so the
  /// keyframe is renewed before tracking degrades; and a frame that sees many planes but matches
  /// few of its keyframe's would leave the rest of what it sees out of its registration and out of
  /// the graph. A frame whose planes all match stays with its keyframe: where only two walls are
  /// in view, renewing the keyframe every frame would chain one relative-pose error per frame.
  int keyframe_min_matches = 6;
  /// Prior covariance of the constant-velocity prediction, per frame: 1 sigma [m] and [rad].
  /// Looser than the real change of velocity between frames (a few millimetres for a hand-held
  /// camera): tighter, the association's prior preference and the gate below refuse the small
  /// planes that fix directions the large ones leave open.
  double prior_translation_sigma = 0.05;
  double prior_rotation_sigma = 0.05;
  /// A tracking result whose correction to the prior has a chi-square (6 dof; covariance: the
  /// result's, the last frame's relative to the keyframe, and one frame's plausible change of
  /// velocity, gate_*_sigma) above this is refused as a wrong association and the prior used;
  /// 22.46 is the 99.9% quantile of chi^2(6). 0 disables the gate.
  double prior_gate_chi2 = 22.46;
  /// The change of velocity in one frame the gate still finds plausible, 1 sigma [m], [rad]:
  /// tighter than the association's prior above, which must admit the small planes that fix
  /// open directions. A sliver of a table top that holds a strip of the table's edge face can
  /// otherwise set the roll of a run of frames several degrees off.
  double gate_translation_sigma = 0.01;
  double gate_rotation_sigma = 0.005;
  /// After this many refused frames in a row the result is accepted anyway (the prior, not the
  /// planes, is then the likelier culprit) [frames].
  int prior_gate_max_refusals = 3;
  /// Keep the last well-determined velocity on degenerate (and refused) frames instead of
  /// re-estimating it from a result whose open directions came from the prior itself (feedback:
  /// a bias there grows frame after frame); translation and rotation separately, each when the
  /// planes left any of its directions open.
  bool hold_velocity_when_degenerate = true;
  /// The velocity of the constant-velocity prediction is the mean rate of the well-determined
  /// frame-to-frame motions of the last this many seconds (0: the last one alone). A single
  /// frame's error then does not become the velocity held through a degenerate stretch [s].
  double velocity_window = 0.5;
  /// While the rotation rate is held (the planes leave a rotation open), continue it along the
  /// Theil-Sen trend of its window (constant angular acceleration) instead of its mean,
  /// which lags a turn that speeds up by a quarter second: one blank wall in view while the
  /// camera turns. Only held rotations follow the trend: on every frame it would add drift where
  /// the planes determine the rotation anyway.
  bool continue_held_turn = true;
  /// Fill directions the planes leave open by point-to-plane alignment of the clouds. Off by
  /// default: its corrections on walls seen at a slant are biased.
  bool point_to_plane_fill = false;
  /// Depth images: fill directions the planes leave open by aligning the pixels outside the
  /// planes to a fused depth map of recent frames (registration/depth_local_map.hpp).
  bool depth_map_fill = true;
  registration::DepthMapConfig depth_map;  ///< its settings (the noise model is the sensor's)
  /// Re-acquisition: once the uncertainty the prior accumulated along directions the planes left
  /// open exceeds this (1-sigma, world translation) [m], each new keyframe's planes are
  /// associated with the map's under that uncertainty (Mahalanobis gate) and the pose is pulled
  /// back onto the map when they pin it down below it. 0 = off, the default: on the synthetic
  /// room it still moves the pose along directions the drift did not affect.
  double reacquire_translation_sigma = 0.0;
  /// Optimise the map planes with the poses: every map plane seen from at least two keyframes
  /// becomes a landmark of the pose graph, each keyframe's detection of it a residual, so a wall
  /// ties together keyframes far apart in the chain without a loop closure.
  bool plane_landmarks = true;
  /// Floors of a detected plane's uncertainty in those residuals: its own covariance (from its
  /// pixels) says nothing of calibration, a plane cut by the image border or a crease [rad], [m].
  double landmark_normal_sigma = 0.005;
  double landmark_offset_sigma = 0.005;
  /// A keyframe's detection joins its map plane's landmark only within these of the plane at
  /// the current poses [deg], [m]. Tighter than the map's own association, which is loose on
  /// purpose (a fragment a few degrees off, or a board a few centimetres in front of its wall,
  /// still extends the wall's outline) but would then pull the poses towards the wrong plane.
  double landmark_gate_deg = 1.0;
  double landmark_gate_offset = 0.015;
  /// Frames between two keyframes take their share of the optimiser's correction of the
  /// odometry edge between them in the output trajectory (else they follow their keyframe
  /// rigidly, and the whole correction shows as a jump at the next keyframe); and where tracking
  /// left translations to the prior, the positions follow the curve through the measured
  /// motion on both sides of the stretch, read over velocity_window; a frame (a keyframe too)
  /// far off the motion of the frames on both sides takes that motion's position
  /// (open_stretches.hpp).
  bool interpolate_frames = true;
  bool loop_closure = true;          ///< search and verify loop closures
  double loop_search_radius = 1.5;   ///< [m] candidate keyframes within this distance
  double loop_max_angle_deg = 60.0;  ///< [deg] and viewing directions within this angle
  int loop_min_keyframe_gap = 10;    ///< [keyframes] candidates are at least this much older
  int loop_max_candidates = 3;       ///< [keyframes] tried per new keyframe (nearest first)
  int loop_min_matches = 4;          ///< [planes] a closure needs this many consistent planes
  double loop_max_residual = 0.02;   ///< [m] RMS plane-offset residual of a verified closure
  /// Prior uncertainty of the relative pose to a loop candidate (accumulated drift) [m], [rad].
  double loop_prior_translation_sigma = 0.3;
  double loop_prior_rotation_sigma = 0.15;
  /// Loop closures are hypotheses (closure_consistency.hpp): a verified closure must agree with
  /// the trajectory estimate (its covariance plus that of the best chain of edges between its two
  /// keyframes; the drift prior above where no chain is short enough) and, pairwise, with the
  /// other closures of a window (cycle through the odometry); the largest mutually consistent
  /// set is accepted. Chi-square threshold of both tests (6 dof): 22.46 is the 99.9% quantile.
  /// After each optimisation a closure whose residual exceeds it is an outlier of the robust
  /// kernel and is retracted.
  double loop_consistency_chi2 = 22.46;
  /// [closures] a consistent set is accepted once it holds this many closures (accepted ones of
  /// the window count): one registration alone never moves the map, as in ORB-SLAM's check of
  /// consecutive consistent candidates.
  int loop_min_support = 2;
  /// [keyframes] a hypothesis waits this long for support before it is rejected; closures
  /// accepted this recently support new ones.
  int loop_window_keyframes = 8;
  /// [keyframes] after accepted closures only this many latest keyframes are optimised first
  /// (the rest held); when that leaves a new closure's residual above loop_consistency_chi2 the
  /// correction reaches further back and the whole graph is optimised. 0: always the whole
  /// graph.
  int local_window_keyframes = 25;
  /// Test hook: this many wrong loop closures (seeded; random keyframe pairs, relative poses off
  /// by 0.1-1 m and 2-20 deg from the estimate, a verified closure's covariance) are offered to
  /// the hypothesis test over the run (needs PlanRun). 0: none.
  int inject_false_closures = 0;
  /// Test hook: seed of the injected closures (frames, keyframe pairs, errors), for families of
  /// draws.
  int inject_seed = 1;
  /// Problems with the values, empty when fine.
  std::vector<std::string> Validate() const;
};

/// What happened to one frame.
struct SlamFrameResult {
  std::size_t index = 0;
  double timestamp = 0.0;
  Pose T_world_sensor = Pose::Identity();  ///< current estimate (before later optimisations)
  bool keyframe = false;
  int planes = 0;                    ///< detected in the frame
  int matches = 0;                   ///< planes matched with the keyframe
  bool tracked = false;              ///< the registration converged (else the prior was used)
  bool degenerate = false;           ///< the planes left some direction undetermined
  bool used_point_to_plane = false;  ///< a degenerate direction was filled by point alignment
  /// What constrained the motion: "planes", "points", "prior" joined by '+'
  /// (registration::ConstraintSource), and how many directions the planes left open.
  std::string constrained_by = "planes";
  int weak_directions = 0;
  int loop_closures = 0;             ///< closures accepted at this frame
  bool refused = false;              ///< the result contradicted the motion prior and was not used
  int closures_rejected = 0;         ///< closure hypotheses rejected at this frame
  int closures_retracted = 0;        ///< accepted closures retracted at this frame (outliers)
};

/// What became of a loop-closure hypothesis.
enum class ClosureStatus { kPending, kAccepted, kRejected, kRetracted };
/// "pending", "accepted", "rejected", "retracted".
const char* ClosureStatusName(ClosureStatus status);

/// One loop-closure hypothesis: a verified registration (or an injected one) and its fate.
struct LoopClosureRecord {
  std::int64_t from_keyframe = 0;  ///< the older keyframe
  std::int64_t to_keyframe = 0;    ///< the new keyframe
  std::size_t from_frame = 0;
  std::size_t to_frame = 0;
  Pose T_from_to = Pose::Identity();        ///< measured relative pose
  Matrix6d covariance = Matrix6d::Zero();  ///< of the measurement (registration convention)
  /// Chi-square against the trajectory estimate when proposed (closure + path covariance).
  double chi2_trajectory = 0.0;
  double chi2_residual = 0.0;  ///< whitened residual^2 after the last optimisation (accepted)
  int support = 0;             ///< size of the consistent set that accepted it
  /// Map planes observed from both keyframes, and how many of them the measured relative pose
  /// maps onto each other (a closure with none, or most of them contradicting it, is rejected).
  int shared_planes = 0;
  int shared_agreeing = 0;
  /// The map around the old keyframe vouches for the closure (SlamSystem::CheckAgainstMap): the
  /// new keyframe's planes, placed by it, lie on the map planes there. Such a closure may
  /// reconnect keyframes whose planes joined different map planes (a stretch of drift made
  /// copies).
  bool map_vouched = false;
  /// What determined the measured relative pose: "planes", "planes+points" (the points of the
  /// two places along the directions the planes leave open), "injected".
  std::string verified_by;
  ClosureStatus status = ClosureStatus::kPending;
  std::string reason;          ///< why accepted, rejected or retracted
  bool injected = false;       ///< a test-hook false closure
  std::size_t decided_frame = 0;  ///< frame at which the status was last set
};

/// Summary counters of a run.
struct SlamStats {
  std::size_t frames = 0;
  std::size_t keyframes = 0;
  std::size_t loop_closures = 0;    ///< verified and added
  std::size_t loop_candidates = 0;  ///< tried
  /// Why tried candidates were refused: the planes left a direction open, too few consistent
  /// matches, residual too large (counted in that order, one reason per candidate).
  std::size_t loop_refused_degenerate = 0;
  std::size_t loop_refused_matches = 0;
  std::size_t loop_refused_residual = 0;
  /// Candidates whose planes also fit a different relative pose without the estimate's anchor.
  std::size_t loop_refused_ambiguous = 0;
  std::size_t closures_rejected = 0;   ///< hypotheses rejected (inconsistent or unsupported)
  std::size_t closures_retracted = 0;  ///< accepted, then outliers of the optimisation
  std::size_t closures_injected = 0;   ///< test-hook false closures offered
  std::size_t local_optimizations = 0;  ///< of optimizations, windowed ones
  /// Keyframes whose accepted closures the estimate already satisfied: no optimisation then.
  std::size_t optimizations_deferred = 0;
  std::size_t map_splits = 0;  ///< map-plane merges undone (observations no longer agreeing)
  std::size_t map_planes_culled = 0;  ///< map planes seldom detected where keyframes saw them
  std::size_t degenerate_frames = 0;
  std::size_t point_to_plane_frames = 0;  ///< degenerate frames filled by point alignment
  std::size_t prior_frames = 0;  ///< frames with some direction (or all) from the motion prior
  std::size_t untracked_frames = 0;       ///< no usable plane registration (prior used)
  std::size_t reacquisition_attempts = 0;  ///< keyframes tried against the map after drift
  std::size_t reacquisitions = 0;          ///< of those, pulled back onto the map
  std::size_t refused_frames = 0;         ///< registration refused by the prior gate (prior used)
  std::size_t optimizations = 0;
  double time_tracking_ms = 0.0;  ///< association + registration, total
  double time_loop_ms = 0.0;      ///< loop-closure search and verification, total
  double time_optimize_ms = 0.0;  ///< pose graph + map refit, total
  double time_map_ms = 0.0;       ///< plane map insertion, total
  /// ProcessFrame time summed over the first and over the last kTimedFrames frames [ms].
  static constexpr std::size_t kTimedFrames = 500;
  double time_first_frames_ms = 0.0;
  double time_last_frames_ms = 0.0;
};

class SlamSystem {
 public:
  SlamSystem(const SlamConfig& config, const registration::AssociationConfig& association,
             const registration::RegistrationConfig& registration,
             const registration::PointToPlaneConfig& point_to_plane,
             const PoseGraphConfig& pose_graph, const PlaneMapConfig& plane_map);

  /// Processes the next frame (in time order) with its detected planes. The first frame defines
  /// the world frame (identity) unless `T_world_first` was set.
  SlamFrameResult ProcessFrame(double timestamp, const datasets::OrganizedCloud& cloud,
                               const detection::Segmentation& segmentation);
  /// Pose of the first frame in the world (e.g. the ground truth's, to compare maps); call before
  /// the first frame.
  void SetInitialPose(const Pose& T_world_first) { T_world_first_ = T_world_first; }
  /// Final pose-graph optimisation and map re-fit. Returns the optimiser's result.
  PoseGraphResult Finish();
  /// Number of frames the run will have: places the injected false closures (test hook
  /// inject_false_closures) over the run.
  void PlanRun(std::size_t frames);
  /// Every loop-closure hypothesis, in the order proposed.
  const std::vector<LoopClosureRecord>& closures() const { return closures_; }

  /// Every processed frame's pose: T_world_keyframe (current graph) * T_keyframe_frame; with
  /// slam.interpolate_frames, outliers and open stretches re-interpolated (open_stretches.hpp),
  /// the outliers' timestamps appended to `outliers`.
  datasets::Trajectory EstimatedTrajectory(std::vector<double>* outliers = nullptr) const;
  /// Keyframe poses (current graph), by keyframe id.
  std::unordered_map<std::int64_t, Pose> KeyframePoses() const;
  /// Frame index of each keyframe id.
  const std::vector<std::size_t>& keyframe_frames() const { return keyframe_frames_; }
  const PoseGraph& graph() const { return graph_; }
  const PlaneMap& map() const { return map_; }
  const SlamStats& stats() const { return stats_; }

 private:
  struct Keyframe {
    std::int64_t id = 0;
    std::size_t frame = 0;
    std::vector<detection::Plane> planes;
    /// Per plane: its outline when wholly in view, for the directions the planes leave open.
    std::vector<registration::PlaneExtent> extents;
    /// Range images: the structure outside the planes (sensor frame, thinned to the alignment's
    /// spacing), for the point alignment of loop closures along the directions the planes leave
    /// open.
    std::vector<registration::CompactShapedPoint> structure;
    std::vector<int> map_planes;  ///< map plane ids its planes joined (ids may since be merged)
    ViewBins view;  ///< what its scan saw (farthest return per direction), for map-plane culling
  };
  /// A loop registration checked against the map around the old keyframe: the new keyframe's
  /// planes, placed by the closure, that lie within a map plane's extent there, and of those the
  /// ones the map plane's offset and normal contradict.
  struct MapCheck {
    int covered = 0;
    int contradicted = 0;
    bool Vouches(int min_matches) const {
      return covered - contradicted >= min_matches && 4 * contradicted <= covered;
    }
  };
  struct FrameRecord {
    double timestamp = 0.0;
    std::int64_t keyframe_id = 0;
    Pose T_keyframe_frame = Pose::Identity();
    /// The directions its tracking left to the prior, world axes (TrackedPose::open).
    Eigen::Matrix<double, 6, Eigen::Dynamic> open = Eigen::Matrix<double, 6, 0>();
  };

  /// Nodes a path search of the consistency tests settles at most.
  static constexpr std::size_t kPathSearchNodes = 400;
  /// A keyframe's structure is kept thinned to this many local-map voxels [-].
  static constexpr double kClosureThinning = 1.0;
  /// The old keyframe of a loop candidate and this many neighbours on each side form the map
  /// its new keyframe's structure is aligned to [keyframes].
  static constexpr std::int64_t kClosureMapNeighbours = 2;
  static constexpr int kClosureMapPointsPerVoxel = 20;  ///< as the tracking's local map
  /// The map planes seen from the old keyframe of a loop candidate and this many keyframes on
  /// each side are the map a closure is checked against [keyframes].
  static constexpr std::int64_t kMapCheckNeighbours = 5;

  Pose KeyframePose(std::int64_t id) const { return graph_.node(id).T_world_node(); }
  SlamFrameResult TrackFrame(double timestamp, const datasets::OrganizedCloud& cloud,
                             const detection::Segmentation& segmentation);
  /// Registers `reg` again without its pairs that contradict the plausible motion
  /// (registration::PlausibleMatches) when its result is suspect and other pairs agree.
  void DropImplausibleMatches(const Keyframe& keyframe, const detection::Segmentation& segmentation,
                              const registration::MotionPrior& prior,
                              const registration::MotionPrior& gate_prior,
                              registration::RegistrationResult* reg) const;
  void AddKeyframe(std::size_t frame, const Pose& T_world_sensor,
                   const detection::Segmentation& segmentation,
                   const datasets::OrganizedCloud& cloud,
                   const std::vector<registration::ShapedPoint>& structure);
  /// Verifies the loop candidates of the new keyframe; the verified ones become hypotheses.
  void SearchLoopClosures(const Keyframe& current, SlamFrameResult* result);
  /// Fills the directions a loop registration's planes leave open by aligning the current
  /// keyframe's structure to that of the old keyframe and its neighbours. Returns whether the
  /// points determined all of them.
  bool FillClosureFromPoints(const Keyframe& old, const Keyframe& current,
                             registration::RegistrationResult* reg) const;
  MapCheck CheckAgainstMap(const Keyframe& old, const Keyframe& current, const Pose& T_old_current,
                           const Matrix6d& covariance) const;
  /// Why a loop registration cannot be a closure: 0 usable, 1 not converged or degenerate, 2 too
  /// few matches, 3 residual too large.
  int VerificationFault(const registration::RegistrationResult& reg) const;
  /// Whether two registrations differ beyond their covariances (chi2 > loop_consistency_chi2).
  bool Differ(const registration::RegistrationResult& a,
              const registration::RegistrationResult& b) const;
  /// Seed of the test hook's random stream (inject_seed).
  std::uint64_t InjectionSeed() const;
  /// The planned false closures of the test hook for this keyframe.
  void InjectFalseClosures(const Keyframe& current, SlamFrameResult* result);
  /// Counts the map planes both keyframes of a closure see and those the closure agrees with.
  void CountSharedPlanes(LoopClosureRecord* record) const;
  /// New hypothesis: tested against the shared map planes and the trajectory estimate, then
  /// pending or rejected.
  void ProposeClosure(LoopClosureRecord record, SlamFrameResult* result);
  /// PCM decision over the window; adds the accepted closures' edges. Returns how many.
  int DecideClosures(std::int64_t current_id, SlamFrameResult* result);
  /// PCM: tests the pairs of hypotheses of `window` not tested yet (pair_consistent_).
  void TestNewPairs(const std::vector<std::size_t>& window);
  /// Optimises after closures were accepted (window or whole graph), then retracts outliers.
  void OptimizeAfterClosures(int accepted, SlamFrameResult* result);
  /// Removes accepted closures whose residual exceeds loop_consistency_chi2. Returns how many.
  int RetractOutliers(std::int64_t first_checked, std::size_t frame);
  /// Pose graph with the plane landmarks (only the keyframes from `first_free` on when >= 0),
  /// then the map re-fitted to the new poses.
  PoseGraphResult Optimize(std::int64_t first_free = -1);
  /// Removes the map planes that keyframes looked at (in view, unoccluded, facing them, within
  /// the range they were detected at) far more often than they detected them. Returns how many.
  int CullUnconfirmedPlanes();
  /// Whether the closure's residual chi-square at the current poses is within
  /// loop_consistency_chi2.
  bool ClosureSatisfied(const LoopClosureRecord& record) const;
  /// Whether every closure accepted at `decided_frame` is satisfied.
  bool ClosuresSatisfied(std::size_t decided_frame) const;
  /// The map planes seen from two or more keyframes, with those keyframes' detections of them.
  std::vector<PlaneLandmark> PlaneLandmarks() const;
  /// After directions were left to the prior (drift_covariance_ above the configured sigma), at
  /// a new keyframe: associates the frame's planes with the map's in Mahalanobis distance under
  /// that drift and moves the pose onto the map when the pairs pin the drift down; the odometry
  /// edge from the keyframe (T_keyframe_curr, covariance) takes the correction and the drift's
  /// uncertainty (slam_reacquisition.cpp). Returns whether it moved the pose.
  bool Reacquire(const detection::Segmentation& segmentation, std::int64_t keyframe_id,
                 Pose* T_world_sensor, Pose* T_keyframe_curr, Matrix6d* covariance);
  /// Adds one frame's prior uncertainty along the directions its tracking left to the prior
  /// (unit columns, world axes) to drift_covariance_.
  void AccumulateDrift(const Eigen::Matrix<double, 6, Eigen::Dynamic>& open);
  /// Adds the frame's motion since the previous one (T_keyframe_last_ to T_keyframe_curr) to the
  /// velocity, holding the parts the prior supplied; `keyframe_frame` is the keyframe's frame.
  void UpdateVelocity(double timestamp, double dt, std::size_t keyframe_frame,
                      bool use_registration, const registration::RegistrationResult& reg,
                      const Pose& T_keyframe_curr);
  /// Depth images: fuses the frame into the depth map (created with the first frame).
  void UpdateDepthMap(const datasets::OrganizedCloud& cloud,
                      const std::vector<std::int32_t>& labels, const Pose& T_world_sensor);
  /// Depth images: fills the directions the planes left open in a converged `reg` (relative to
  /// the keyframe) from the depth map, or where it does not pin them down, by projective
  /// point-to-plane against the keyframe's cloud (point_to_plane_fill). Returns whether the
  /// points filled a direction.
  bool FillFromDepthImage(std::int64_t keyframe_id, const datasets::OrganizedCloud& cloud,
                          const std::vector<std::int32_t>& labels,
                          registration::RegistrationResult* reg) const;

  SlamConfig config_;
  registration::AssociationConfig association_config_;
  registration::RegistrationConfig registration_config_;
  registration::PointToPlaneConfig point_to_plane_config_;
  /// The current keyframe's cloud and the pinhole grid it came from, for the point-to-plane fill
  /// of directions the planes cannot determine (none for spherical sensors).
  datasets::OrganizedCloud keyframe_cloud_;
  std::optional<datasets::PinholeIntrinsics> intrinsics_;
  /// Range images (LiDAR): the local map of recent frames' structure that fills the directions
  /// the planes leave open (registration/local_map.hpp); cleared when the graph moves the poses.
  std::unique_ptr<registration::LocalVoxelMap> local_map_;
  /// Depth images: the fused depth map of recent frames (SlamConfig::depth_map_fill); moved with
  /// the current keyframe when the graph moves the poses.
  std::unique_ptr<registration::DepthLocalMap> depth_map_;
  /// Uncertainty of the current pose in the world (world-aligned (dt, dtheta)) accumulated along
  /// the directions filled from the motion prior since the map last pinned the pose down.
  Matrix6d drift_covariance_ = Matrix6d::Zero();
  /// The first range image, until the second frame's motion is bootstrapped from it (no velocity
  /// yet: registration::AlignScansCoarseToFine).
  datasets::OrganizedCloud first_cloud_;
  PoseGraphConfig pose_graph_config_;
  PoseGraph graph_;
  PlaneMap map_;
  std::vector<Keyframe> keyframes_;
  std::vector<std::size_t> keyframe_frames_;
  std::vector<FrameRecord> frames_;
  Pose T_world_first_ = Pose::Identity();
  registration::VelocityModel velocity_;  ///< of the well-determined frames
  Pose T_keyframe_last_ = Pose::Identity();
  Matrix6d covariance_keyframe_last_ = Matrix6d::Zero();  ///< of T_keyframe_last_
  int consecutive_refusals_ = 0;
  /// The last frames whose translation and rotation the velocity took (not held).
  std::size_t translation_measured_at_ = 0, rotation_measured_at_ = 0;
  SlamStats stats_;
  std::vector<LoopClosureRecord> closures_;
  std::vector<std::size_t> pending_;  ///< indices into closures_ awaiting a decision
  /// Accepted closures in the graph: (from, to) keyframes -> record.
  std::map<std::pair<std::int64_t, std::int64_t>, std::size_t> accepted_edges_;
  std::map<std::pair<std::size_t, std::size_t>, bool> pair_consistent_;  ///< PCM cache
  std::unique_ptr<GraphPaths> paths_;  ///< chains of edges for the consistency tests
  std::vector<std::size_t> injection_frames_;  ///< planned frames of injected closures, sorted
  std::size_t next_injection_ = 0;
  std::uint64_t injection_state_ = 0;
  std::deque<double> recent_frame_ms_;  ///< ProcessFrame times of the last kTimedFrames frames
};

}  // namespace planeslam::mapping

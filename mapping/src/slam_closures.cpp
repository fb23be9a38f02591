// Loop closures as hypotheses (SlamSystem): verification by plane registration, the trajectory
// and pairwise (PCM) consistency tests, acceptance of the largest consistent set, optimisation
// (window or whole graph) and retraction of the robust kernel's outliers; and the test hook that
// injects false closures.
#include <algorithm>
#include <random>
#include <sstream>
#include <unordered_set>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/mapping/loop_registration.hpp"
#include "planeslam/mapping/slam_system.hpp"
#include "slam_internal.hpp"

namespace planeslam::mapping {

using namespace slam_internal;  // NOLINT: the helpers shared with slam_system.cpp

namespace {

constexpr std::uint64_t kInjectionSeed = 0x5eed'c105'0000ULL;

/// Uniform in [0, 1) from 53 random bits (independent of the standard library's distributions).
double Uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

Eigen::Vector3d RandomDirection(std::mt19937_64& rng) {
  const double z = 2.0 * Uniform(rng) - 1.0;
  const double phi = 2.0 * M_PI * Uniform(rng);
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

std::string Format(const char* what, double value) {
  std::ostringstream os;
  os.precision(3);
  os << what << value;
  return os.str();
}

}  // namespace

const char* ClosureStatusName(ClosureStatus status) {
  switch (status) {
    case ClosureStatus::kPending:
      return "pending";
    case ClosureStatus::kAccepted:
      return "accepted";
    case ClosureStatus::kRejected:
      return "rejected";
    case ClosureStatus::kRetracted:
      return "retracted";
  }
  return "unknown";
}

std::uint64_t SlamSystem::InjectionSeed() const {
  // Seed 1 gives the draws the hook has always made; others shift the stream far apart.
  return kInjectionSeed + 1 + (static_cast<std::uint64_t>(config_.inject_seed) - 1) * 0x10000ULL;
}

void SlamSystem::PlanRun(std::size_t frames) {
  injection_frames_.clear();
  next_injection_ = 0;
  if (config_.inject_false_closures <= 0 || frames == 0) return;
  std::mt19937_64 rng(InjectionSeed());
  for (int k = 0; k < config_.inject_false_closures; ++k) {
    injection_frames_.push_back(static_cast<std::size_t>(Uniform(rng) * frames));
  }
  std::sort(injection_frames_.begin(), injection_frames_.end());
}

void SlamSystem::SearchLoopClosures(const Keyframe& current, SlamFrameResult* result) {
  const Pose T_world_current = KeyframePose(current.id);
  struct Candidate {
    double distance;
    std::size_t index;
  };
  std::vector<Candidate> candidates;
  // Every older keyframe is a possible candidate; the distance, read from the node's position,
  // rules out most of them, and the angle between the viewing directions (of the relative
  // rotation, from the quaternions' dot product) more. Keyframe i is the graph's node i, with id
  // i (AddKeyframe adds both), so the nodes are read in order rather than looked up by id.
  const std::vector<PoseGraphNode>& nodes = graph_.nodes();
  PLANESLAM_CHECK(nodes.size() == keyframes_.size(), "one pose graph node per keyframe");
  const Eigen::Quaterniond q_current = Eigen::Quaterniond(T_world_current.linear()).normalized();
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    if (nodes[i].id > current.id - config_.loop_min_keyframe_gap) break;
    const double distance = (nodes[i].position - T_world_current.translation()).norm();
    if (!(distance < config_.loop_search_radius)) continue;
    const double cos_half = std::abs(nodes[i].rotation.normalized().dot(q_current));
    const double angle = 2.0 * std::acos(std::min(1.0, cos_half));
    if (angle < config_.loop_max_angle_deg * kDegToRad) candidates.push_back({distance, i});
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    return a.distance < b.distance || (a.distance == b.distance && a.index < b.index);
  });
  if (static_cast<int>(candidates.size()) > config_.loop_max_candidates) {
    candidates.resize(config_.loop_max_candidates);
  }

  LoopRegistrationConfig loop_config;
  loop_config.prior_translation_sigma = config_.loop_prior_translation_sigma;
  loop_config.prior_rotation_sigma = config_.loop_prior_rotation_sigma;
  loop_config.search_radius = config_.loop_search_radius;
  loop_config.association = association_config_;
  loop_config.registration = registration_config_;
  for (const Candidate& candidate : candidates) {
    const Keyframe& old = keyframes_[candidate.index];
    ++stats_.loop_candidates;
    const Pose T_old_current = KeyframePose(old.id).inverse() * T_world_current;
    registration::RegistrationResult anchored =
        AnchoredLoopRegistration(old.planes, current.planes, T_old_current, loop_config);
    if (anchored.converged && anchored.degenerate) FillClosureFromPoints(old, current, &anchored);
    const int fault = VerificationFault(anchored);
    // A second well-determined solution without the anchor: the anchor's offset gate loses the
    // true partners after a drift of decimetres, and where both are determined and differ, the
    // planes do not single out one relative pose. The map around the old keyframe then decides:
    // a solution is taken when the new keyframe's planes, placed by it, lie on the map planes
    // there and the other solution's do not. (The unanchored solution alone is not trusted:
    // where the anchored one finds nothing, it picks the wrong face about as often as the right
    // one.)
    const registration::RegistrationResult unanchored =
        UnanchoredLoopRegistration(old.planes, current.planes, T_old_current, loop_config);
    const bool unanchored_usable = VerificationFault(unanchored) == 0;
    // An unanchored solution too loose for a closure of its own still shows, where the planes
    // support it as well, that the anchored one rests on the estimate (loop_registration.hpp).
    if (fault == 0 && !unanchored_usable &&
        UnanchoredRivalsAnchored(anchored, unanchored, config_.loop_consistency_chi2)) {
      ++stats_.loop_refused_ambiguous;
      continue;
    }
    const registration::RegistrationResult* chosen = fault == 0 ? &anchored : nullptr;
    bool vouched = false;
    if (unanchored_usable && (fault != 0 || Differ(anchored, unanchored))) {
      const bool u = CheckAgainstMap(old, current, unanchored.T_prev_curr, unanchored.covariance)
                         .Vouches(config_.loop_min_matches);
      const bool a =
          fault == 0 && CheckAgainstMap(old, current, anchored.T_prev_curr, anchored.covariance)
                            .Vouches(config_.loop_min_matches);
      chosen = u && !a ? &unanchored : nullptr;
      vouched = chosen != nullptr;
      if (!chosen && fault == 0) {
        ++stats_.loop_refused_ambiguous;
        continue;
      }
    }
    if (!chosen) {
      ++(fault == 1 ? stats_.loop_refused_degenerate
                    : fault == 2 ? stats_.loop_refused_matches : stats_.loop_refused_residual);
      continue;
    }
    const registration::RegistrationResult& reg = *chosen;
    LoopClosureRecord record;
    record.from_keyframe = old.id;
    record.to_keyframe = current.id;
    record.from_frame = old.frame;
    record.to_frame = current.frame;
    record.T_from_to = reg.T_prev_curr;
    record.covariance = reg.covariance;
    record.map_vouched = vouched;
    record.verified_by = registration::ConstraintSource(reg);
    ProposeClosure(std::move(record), result);
  }
}

bool SlamSystem::FillClosureFromPoints(const Keyframe& old, const Keyframe& current,
                                       registration::RegistrationResult* reg) const {
  // A street or a corridor: ground and facades leave the driving direction open. The points
  // outside the planes (poles, edges, door recesses, clutter) of the old keyframe and its
  // neighbours, placed by the current estimate relative to the old keyframe, form a map the new
  // keyframe's structure is aligned to along the open directions, the planes' solution as the
  // prior (registration/local_map.hpp). The neighbours densify the map; their placement relies
  // on a few keyframes of odometry only.
  if (!local_map_ || current.structure.empty() || old.structure.empty()) return false;
  registration::LocalVoxelMap map(local_map_->voxel_size(), kClosureMapPointsPerVoxel);
  const Pose T_old_world = KeyframePose(old.id).inverse();
  const std::int64_t last = current.id - config_.loop_min_keyframe_gap;
  for (std::int64_t id = std::max<std::int64_t>(0, old.id - kClosureMapNeighbours);
       id <= std::min(last, old.id + kClosureMapNeighbours); ++id) {
    map.Insert(keyframes_[static_cast<std::size_t>(id)].structure, T_old_world * KeyframePose(id),
               0.0);
  }
  registration::FillDegenerateFromLocalMap(
      map, Pose::Identity(), registration::ExpandShapedPoints(current.structure), {}, reg);
  return reg->used_icp && reg->prior_directions == 0;
}

int SlamSystem::VerificationFault(const registration::RegistrationResult& reg) const {
  // Only a closure fully determined, by the planes or by the points where the planes leave
  // directions open, may correct the trajectory: a degenerate one would carry the (drifted)
  // prior into the graph as if it were a measurement.
  if (!reg.converged || (reg.degenerate && !(reg.used_icp && reg.prior_directions == 0))) {
    return 1;
  }
  if (static_cast<int>(reg.inliers.size()) < config_.loop_min_matches) return 2;
  if (!(reg.residual_rms < config_.loop_max_residual)) return 3;
  return 0;
}

bool SlamSystem::Differ(const registration::RegistrationResult& a,
                        const registration::RegistrationResult& b) const {
  // Two well-determined solutions further apart than their covariances allow: the planes do
  // not single out one relative pose, and the closure is refused rather than trusted to the
  // prior.
  return RegistrationDifferenceChi2(a, b) > config_.loop_consistency_chi2;
}

void SlamSystem::InjectFalseClosures(const Keyframe& current, SlamFrameResult* result) {
  // Each planned closure links this keyframe to a random older one (not its predecessor) with
  // the estimate's relative pose off by 0.1-1 m and 2-20 deg: plausible for a registration, wrong
  // for the world. Its covariance is a verified closure's (the last one, else 1 cm / 0.3 deg).
  std::mt19937_64 rng(InjectionSeed() + static_cast<std::uint64_t>(current.id));
  while (current.id >= 2 && next_injection_ < injection_frames_.size() &&
         injection_frames_[next_injection_] <= current.frame) {
    ++next_injection_;
    const auto old_id =
        static_cast<std::int64_t>(Uniform(rng) * static_cast<double>(current.id - 1));
    Vector6d error;
    error.head<3>() = (0.1 + 0.9 * Uniform(rng)) * RandomDirection(rng);
    error.tail<3>() = (2.0 + 18.0 * Uniform(rng)) * kDegToRad * RandomDirection(rng);
    LoopClosureRecord record;
    record.from_keyframe = old_id;
    record.to_keyframe = current.id;
    record.from_frame = keyframes_[static_cast<std::size_t>(old_id)].frame;
    record.to_frame = current.frame;
    record.T_from_to =
        registration::BoxPlus(KeyframePose(old_id).inverse() * KeyframePose(current.id), error);
    const auto verified = std::find_if(closures_.rbegin(), closures_.rend(),
                                       [](const LoopClosureRecord& r) { return !r.injected; });
    record.covariance =
        verified != closures_.rend() ? verified->covariance : DiagonalCovariance(0.01, 0.005);
    record.injected = true;
    record.verified_by = "injected";
    ++stats_.closures_injected;
    ProposeClosure(std::move(record), result);
  }
}

SlamSystem::MapCheck SlamSystem::CheckAgainstMap(const Keyframe& old, const Keyframe& current,
                                                 const Pose& T_old_current,
                                                 const Matrix6d& covariance) const {
  // The map planes the old keyframe and its neighbours joined: the map of that place, seen
  // from keyframes whose poses agree with one another.
  std::unordered_set<int> near;
  const std::int64_t last = current.id - config_.loop_min_keyframe_gap;
  for (std::int64_t id = std::max<std::int64_t>(0, old.id - kMapCheckNeighbours);
       id <= std::min(last, old.id + kMapCheckNeighbours); ++id) {
    for (int map_id : keyframes_[static_cast<std::size_t>(id)].map_planes) {
      const int resolved = map_id > 0 ? map_.ResolveId(map_id) : -1;
      if (resolved > 0) near.insert(resolved);
    }
  }
  const Pose T_world_current = KeyframePose(old.id) * T_old_current;
  const Eigen::Matrix3d translation_cov = KeyframePose(old.id).linear() *
                                          covariance.topLeftCorner<3, 3>() *
                                          KeyframePose(old.id).linear().transpose();
  const double rotation_var = covariance.bottomRightCorner<3, 3>().trace() / 3.0;
  const double cos_gate = std::cos(map_.config().max_normal_angle_deg * kDegToRad);
  MapCheck check;
  for (const detection::Plane& plane : current.planes) {
    if (plane.point_count < map_.config().min_observation_points) continue;
    const Eigen::Vector3d n = T_world_current.linear() * plane.normal;
    const Eigen::Vector3d c = T_world_current * plane.centroid;
    bool covered = false, agrees = false;
    for (int id : near) {
      const MapPlane* map_plane = map_.Find(id);
      if (!map_plane || map_plane->normal.dot(n) < cos_gate) continue;
      // Within the map plane's extent: the centroid's in-plane offset from the map plane's
      // centre inside twice the spread of its points (a uniform rectangle's half side is 1.7).
      const Eigen::Vector3d u = c - map_plane->centroid;
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - n * n.transpose();
      const double count = static_cast<double>(std::max<std::int64_t>(1, map_plane->point_count()));
      const Eigen::Matrix3d spread =
          P * (map_plane->stats_world.scatter / count) * P + n * n.transpose();
      if (!((P * u).dot(spread.ldlt().solve(P * u)) <= 4.0)) continue;
      covered = true;
      const double angle = std::acos(std::clamp(map_plane->normal.dot(n), -1.0, 1.0));
      const double offset = map_plane->normal.dot(c) - map_plane->d;
      const double angle_var = config_.landmark_normal_sigma * config_.landmark_normal_sigma +
                               0.5 * plane.covariance.topLeftCorner<3, 3>().trace() + rotation_var;
      const double offset_var = config_.landmark_offset_sigma * config_.landmark_offset_sigma +
                                plane.covariance(3, 3) + n.dot(translation_cov * n) +
                                rotation_var * (c - T_world_current.translation()).squaredNorm();
      if (angle * angle / angle_var + offset * offset / offset_var <=
          association_config_.inlier_chi2) {
        agrees = true;
        break;
      }
    }
    check.covered += covered ? 1 : 0;
    check.contradicted += covered && !agrees ? 1 : 0;
  }
  return check;
}

void SlamSystem::CountSharedPlanes(LoopClosureRecord* record) const {
  // Map planes observed from both keyframes: the closure maps the old keyframe's detection of
  // each onto the new keyframe's (n_to = R^T n_from, d_to = d_from - n_from . t). They tie the two
  // keyframes through the plane landmarks, which the chain covariances of the consistency tests
  // know nothing of: a degenerate stretch of odometry leaves those loose, while the walls both
  // keyframes see fix the relative pose to millimetres.
  const auto detection = [&](std::int64_t keyframe, int detection_id) -> const detection::Plane* {
    const auto& planes = keyframes_[static_cast<std::size_t>(keyframe)].planes;
    const int k = detection_id - 1;
    return k >= 0 && k < static_cast<int>(planes.size()) ? &planes[static_cast<std::size_t>(k)]
                                                         : nullptr;
  };
  const Eigen::Matrix3d R = record->T_from_to.linear();
  const Eigen::Vector3d t = record->T_from_to.translation();
  const Eigen::Matrix3d translation_cov = record->covariance.topLeftCorner<3, 3>();
  const double rotation_var = record->covariance.bottomRightCorner<3, 3>().trace() / 3.0;
  record->shared_planes = record->shared_agreeing = 0;
  for (const MapPlane& plane : map_.planes()) {
    const detection::Plane* from = nullptr;
    const detection::Plane* to = nullptr;
    for (const PlaneObservation& obs : plane.observations) {
      if (obs.keyframe_id == record->from_keyframe && !from) {
        from = detection(obs.keyframe_id, obs.detection_id);
      } else if (obs.keyframe_id == record->to_keyframe && !to) {
        to = detection(obs.keyframe_id, obs.detection_id);
      }
    }
    if (!from || !to) continue;
    ++record->shared_planes;
    const Eigen::Vector3d n_predicted = R.transpose() * from->normal;
    const double d_predicted = from->d - from->normal.dot(t);
    const double angle = std::acos(std::clamp(n_predicted.dot(to->normal), -1.0, 1.0));
    // Variances: the landmark floors, both detections' own, the closure's along the plane.
    const double angle_var = config_.landmark_normal_sigma * config_.landmark_normal_sigma +
                             0.5 * (from->covariance.topLeftCorner<3, 3>().trace() +
                                    to->covariance.topLeftCorner<3, 3>().trace()) +
                             rotation_var;
    const double offset_var = config_.landmark_offset_sigma * config_.landmark_offset_sigma +
                              from->covariance(3, 3) + to->covariance(3, 3) +
                              from->normal.dot(translation_cov * from->normal);
    const double offset = d_predicted - to->d;
    const double chi2 = angle * angle / angle_var + offset * offset / offset_var;
    if (chi2 <= association_config_.inlier_chi2) ++record->shared_agreeing;
  }
}

void SlamSystem::ProposeClosure(LoopClosureRecord record, SlamFrameResult* result) {
  record.decided_frame = record.to_frame;
  CountSharedPlanes(&record);
  // Keyframes that share no map plane are tied only by chains of odometry, which stay loose
  // where the planes left directions open: neither the trajectory test nor the pairwise one then
  // has the power to reject a closure decimetres off, so the map must vouch for it.
  const bool unshared = record.shared_planes == 0 && !record.map_vouched;
  if (unshared || 2 * record.shared_agreeing < record.shared_planes) {
    record.status = ClosureStatus::kRejected;
    record.reason = unshared ? std::string("the keyframes share no map plane")
                             : "contradicted by the map planes both keyframes see (" +
                                   std::to_string(record.shared_planes - record.shared_agreeing) +
                                   " of " + std::to_string(record.shared_planes) + ")";
    ++stats_.closures_rejected;
    ++result->closures_rejected;
    closures_.push_back(std::move(record));
    return;
  }
  // The estimate's relative pose with the uncertainty of the best chain of edges between the two
  // keyframes; without a short chain, the drift the loop search assumes.
  const Pose T_estimate =
      KeyframePose(record.from_keyframe).inverse() * KeyframePose(record.to_keyframe);
  UncertainPose estimate{T_estimate, DiagonalCovariance(config_.loop_prior_translation_sigma,
                                                        config_.loop_prior_rotation_sigma)};
  if (const auto path = paths_->Relative(record.from_keyframe, record.to_keyframe)) {
    estimate.covariance = path->covariance;
  }
  const UncertainPose deviation =
      Compose(Invert(estimate), UncertainPose{record.T_from_to, record.covariance});
  record.chi2_trajectory = IdentityChi2(deviation);
  if (!(record.chi2_trajectory <= config_.loop_consistency_chi2)) {
    record.status = ClosureStatus::kRejected;
    record.reason = Format("inconsistent with the trajectory: chi2 ", record.chi2_trajectory);
    ++stats_.closures_rejected;
    ++result->closures_rejected;
  } else {
    pending_.push_back(closures_.size());
  }
  closures_.push_back(std::move(record));
}

void SlamSystem::TestNewPairs(const std::vector<std::size_t>& window) {
  // Each hypothesis meets the older ones of the window it has not met yet; the chains between
  // their keyframes come from one path search back from each of its two keyframes. Without a
  // short chain, the drift the loop search assumes.
  const auto chain = [&](const std::optional<UncertainPose>& path, std::int64_t from,
                         std::int64_t to) {
    if (path) return *path;
    return UncertainPose{KeyframePose(from).inverse() * KeyframePose(to),
                         DiagonalCovariance(config_.loop_prior_translation_sigma,
                                            config_.loop_prior_rotation_sigma)};
  };
  for (const std::size_t b : window) {
    std::vector<std::size_t> older;
    for (const std::size_t a : window) {
      if (a < b && pair_consistent_.find({a, b}) == pair_consistent_.end()) older.push_back(a);
    }
    if (older.empty()) continue;
    const LoopClosureRecord& B = closures_[b];
    std::vector<std::int64_t> new_keyframes, old_keyframes;
    for (const std::size_t a : older) {
      new_keyframes.push_back(closures_[a].to_keyframe);
      old_keyframes.push_back(closures_[a].from_keyframe);
    }
    const auto new_chains = paths_->RelativeFrom(new_keyframes, B.to_keyframe);
    const auto old_chains = paths_->RelativeFrom(old_keyframes, B.from_keyframe);
    for (std::size_t k = 0; k < older.size(); ++k) {
      const LoopClosureRecord& A = closures_[older[k]];
      // Cycle from A's old keyframe: A's closure, the chain between the new keyframes, B's
      // closure backwards, the chain between the old keyframes backwards.
      const UncertainPose cycle =
          Compose(Compose(Compose(UncertainPose{A.T_from_to, A.covariance},
                                  chain(new_chains[k], A.to_keyframe, B.to_keyframe)),
                          Invert(UncertainPose{B.T_from_to, B.covariance})),
                  Invert(chain(old_chains[k], A.from_keyframe, B.from_keyframe)));
      pair_consistent_[{older[k], b}] = IdentityChi2(cycle) <= config_.loop_consistency_chi2;
    }
  }
}

int SlamSystem::DecideClosures(std::int64_t current_id, SlamFrameResult* result) {
  if (pending_.empty()) return 0;
  const std::int64_t window_start = current_id - config_.loop_window_keyframes;
  // The window: the pending hypotheses and the closures accepted within it (support).
  // Hypotheses are proposed as their new keyframe is added, so closures_ is ordered by it.
  std::vector<std::size_t> window;
  for (std::size_t index = closures_.size(); index-- > 0;) {
    const LoopClosureRecord& record = closures_[index];
    if (record.to_keyframe < window_start) break;
    if (record.status != ClosureStatus::kAccepted) continue;
    const auto edge = accepted_edges_.find({record.from_keyframe, record.to_keyframe});
    if (edge != accepted_edges_.end() && edge->second == index) window.push_back(index);
  }
  std::reverse(window.begin(), window.end());
  window.insert(window.end(), pending_.begin(), pending_.end());
  const std::size_t n = window.size();
  TestNewPairs(window);
  std::vector<std::vector<bool>> adjacent(n, std::vector<bool>(n, false));
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      adjacent[i][j] = adjacent[j][i] =
          pair_consistent_.at({std::min(window[i], window[j]), std::max(window[i], window[j])});
    }
  }
  const std::vector<int> clique = MaximumClique(adjacent);
  const int support = static_cast<int>(clique.size());
  std::vector<bool> in_clique(n, false);
  for (int k : clique) in_clique[static_cast<std::size_t>(k)] = true;

  int accepted = 0;
  std::vector<std::size_t> still_pending;
  const std::size_t frame =
      keyframes_[static_cast<std::size_t>(std::min<std::int64_t>(
                     current_id, static_cast<std::int64_t>(keyframes_.size()) - 1))]
          .frame;
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t index = window[k];
    LoopClosureRecord& record = closures_[index];
    if (record.status != ClosureStatus::kPending) continue;
    if (in_clique[k] && support >= config_.loop_min_support) {
      record.status = ClosureStatus::kAccepted;
      record.support = support;
      record.reason = "in the largest consistent set (" + std::to_string(support) + ")";
      record.decided_frame = frame;
      graph_.AddEdge(record.from_keyframe, record.to_keyframe, record.T_from_to,
                     InformationFromCovariance(record.covariance), EdgeKind::kLoopClosure);
      paths_->AddEdge(graph_.edges().back());
      accepted_edges_[{record.from_keyframe, record.to_keyframe}] = index;
      ++accepted;
    } else if (record.to_keyframe < window_start) {
      record.status = ClosureStatus::kRejected;
      record.reason = support >= config_.loop_min_support
                          ? "outside the largest consistent set (" + std::to_string(support) + ")"
                          : "no consistent support within the window";
      record.decided_frame = frame;
      ++stats_.closures_rejected;
      ++result->closures_rejected;
    } else {
      still_pending.push_back(index);
    }
  }
  pending_ = std::move(still_pending);
  // Pairs of hypotheses that left the window are not asked again.
  const std::size_t oldest = window.empty() ? 0 : *std::min_element(window.begin(), window.end());
  pair_consistent_.erase(pair_consistent_.begin(), pair_consistent_.lower_bound({oldest, 0}));
  stats_.loop_closures += static_cast<std::size_t>(accepted);
  return accepted;
}

bool SlamSystem::ClosureSatisfied(const LoopClosureRecord& record) const {
  const Vector6d e = registration::BoxMinus(
      record.T_from_to,
      KeyframePose(record.from_keyframe).inverse() * KeyframePose(record.to_keyframe));
  return e.dot(InformationFromCovariance(record.covariance) * e) <= config_.loop_consistency_chi2;
}

bool SlamSystem::ClosuresSatisfied(std::size_t decided_frame) const {
  return std::all_of(closures_.begin(), closures_.end(), [&](const LoopClosureRecord& record) {
    return record.status != ClosureStatus::kAccepted || record.decided_frame != decided_frame ||
           ClosureSatisfied(record);
  });
}

void SlamSystem::OptimizeAfterClosures(int accepted, SlamFrameResult* result) {
  const auto start = std::chrono::steady_clock::now();
  const std::int64_t current_id = keyframes_.back().id;
  // Closures the estimate already satisfies (the residual test an optimisation would apply
  // afterwards) would move the poses by less than their own noise: they wait in the graph for
  // the next optimisation. In a place revisited lap after lap most closures are of this kind,
  // and optimising after each would make the back end's cost grow with the run.
  if (ClosuresSatisfied(keyframes_.back().frame)) {
    ++stats_.optimizations_deferred;
    return;
  }
  // The latest keyframes are optimised first (warm start from the current poses); when that
  // leaves a new closure unsatisfied (residual chi-square above loop_consistency_chi2) the
  // correction reaches further back and the whole graph is optimised.
  const bool window = config_.local_window_keyframes > 0 &&
                      current_id >= 2 * static_cast<std::int64_t>(config_.local_window_keyframes);
  bool whole = !window;
  if (window) {
    const std::int64_t first_free = current_id - config_.local_window_keyframes + 1;
    Optimize(first_free);
    for (std::size_t k = closures_.size(); !whole && k-- > 0 && accepted > 0;) {
      const LoopClosureRecord& record = closures_[k];
      if (record.status != ClosureStatus::kAccepted || record.to_keyframe != current_id) continue;
      --accepted;
      whole = !ClosureSatisfied(record);
    }
  }
  if (whole) Optimize();
  int retracted = RetractOutliers(0, keyframes_.back().frame);
  // Without its outliers the graph is optimised again, whole (they may have bent all of it).
  for (int round = 0; retracted > 0 && round < 3; ++round) {
    result->closures_retracted += retracted;
    Optimize();
    retracted = RetractOutliers(0, keyframes_.back().frame);
  }
  stats_.time_optimize_ms += ElapsedMs(start);
}

int SlamSystem::RetractOutliers(std::int64_t first_checked, std::size_t frame) {
  int retracted = 0;
  auto& edges = graph_.edges();
  for (std::size_t k = 0; k < edges.size();) {
    const PoseGraphEdge& edge = edges[k];
    const auto found = accepted_edges_.find({edge.from, edge.to});
    if (edge.kind != EdgeKind::kLoopClosure || edge.to < first_checked ||
        found == accepted_edges_.end()) {
      ++k;
      continue;
    }
    LoopClosureRecord& record = closures_[found->second];
    record.chi2_residual = EvaluateEdgeResidual(edge, ToAmbient(KeyframePose(edge.from)),
                                                ToAmbient(KeyframePose(edge.to)))
                               .residual.squaredNorm();
    if (record.chi2_residual <= config_.loop_consistency_chi2) {
      ++k;
      continue;
    }
    record.status = ClosureStatus::kRetracted;
    record.reason = Format("outlier of the optimisation: residual chi2 ", record.chi2_residual);
    record.decided_frame = frame;
    paths_->RemoveEdge(edge.from, edge.to);
    accepted_edges_.erase(found);
    edges.erase(edges.begin() + static_cast<std::ptrdiff_t>(k));
    ++retracted;
    ++stats_.closures_retracted;
  }
  return retracted;
}

}  // namespace planeslam::mapping
